//! Marker sets: which markers give which joint centre, calibration on the static trial and
//! reconstruction of joint centres in movement trials.
//!
//! A joint is either measured directly (the mean of its markers, e.g. the fingertip marker) or
//! carried by a technical cluster: its anatomical landmarks (e.g. the two humeral epicondyles,
//! whose midpoint is the elbow) are seen only in the static trial, where they are expressed
//! relative to the cluster; in every movement frame a least-squares rigid fit (Kabsch, with the
//! reflection guard) of the cluster markers present (at least three) carries them along.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::{ArmSide, ArmTrajectory, MarkerData};
use crate::error::{Error, Result};

/// Where one joint centre comes from. Marker names may contain `{S}`, replaced by the arm's
/// prefix (`R` or `L`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSource {
    /// Markers averaged to give the joint centre (anatomical landmarks when `cluster` is set).
    pub markers: Vec<String>,
    /// The technical cluster that carries the landmarks in movement trials; empty when the
    /// markers are measured directly in every trial.
    #[serde(default)]
    pub cluster: Vec<String>,
}

/// A marker set: the sources of shoulder p, elbow q, optional wrist and fingertip r, and the
/// markers whose left-to-right direction in the static trial gives the actor's heading.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkerSet {
    /// A name for messages and provenance.
    pub name: String,
    /// Shoulder p.
    pub shoulder: JointSource,
    /// Elbow q.
    pub elbow: JointSource,
    /// Wrist (optional; carried along, not used by the models).
    #[serde(default)]
    pub wrist: Option<JointSource>,
    /// Fingertip r.
    pub fingertip: JointSource,
    /// Markers on the actor's right side (their centroid), for the automatic heading.
    #[serde(default)]
    pub heading_right: Vec<String>,
    /// Markers on the actor's left side (their centroid), for the automatic heading.
    #[serde(default)]
    pub heading_left: Vec<String>,
}

impl Default for MarkerSet {
    fn default() -> Self {
        Self::ue_adl()
    }
}

fn names(prefix: &str, base: &str, n: usize) -> Vec<String> {
    (1..=n).map(|k| format!("{prefix}{base}{k}")).collect()
}

impl MarkerSet {
    /// The UE-ADL marker set: shoulder = GTH via the SHO cluster, elbow = midpoint of LEP/MEP
    /// via UAR, wrist = midpoint of SPR/SPU via LAR, fingertip = FTP measured directly; heading
    /// from the RSHO and LSHO clusters.
    pub fn ue_adl() -> Self {
        let s = |v: &[&str]| v.iter().map(|m| format!("{{S}}{m}")).collect::<Vec<_>>();
        MarkerSet {
            name: "ue-adl".into(),
            shoulder: JointSource {
                markers: s(&["GTH"]),
                cluster: names("{S}", "SHO", 4),
            },
            elbow: JointSource {
                markers: s(&["LEP", "MEP"]),
                cluster: names("{S}", "UAR", 4),
            },
            wrist: Some(JointSource {
                markers: s(&["SPR", "SPU"]),
                cluster: names("{S}", "LAR", 4),
            }),
            fingertip: JointSource {
                markers: s(&["FTP"]),
                cluster: Vec::new(),
            },
            heading_right: names("R", "SHO", 4),
            heading_left: names("L", "SHO", 4),
        }
    }

    fn joints(&self) -> Vec<(&'static str, &JointSource)> {
        let mut v = vec![("shoulder", &self.shoulder), ("elbow", &self.elbow)];
        if let Some(w) = &self.wrist {
            v.push(("wrist", w));
        }
        v.push(("fingertip", &self.fingertip));
        v
    }

    /// Markers a static trial must contain for `side` (landmarks, clusters, heading markers).
    pub fn static_markers(&self, side: ArmSide) -> Vec<String> {
        let mut out = Vec::new();
        for (_, j) in self.joints() {
            for m in j.markers.iter().chain(&j.cluster) {
                push_unique(&mut out, subst(m, side));
            }
        }
        for m in self.heading_right.iter().chain(&self.heading_left) {
            push_unique(&mut out, subst(m, side));
        }
        out
    }

    /// Markers a movement trial must contain for `side` (clusters and directly measured markers).
    pub fn movement_markers(&self, side: ArmSide) -> Vec<String> {
        let mut out = Vec::new();
        for (_, j) in self.joints() {
            let src = if j.cluster.is_empty() {
                &j.markers
            } else {
                &j.cluster
            };
            for m in src {
                push_unique(&mut out, subst(m, side));
            }
        }
        out
    }

    /// Checks that every joint has markers and every cluster at least three.
    pub fn check(&self) -> Result<()> {
        for (name, j) in self.joints() {
            if j.markers.is_empty() {
                return Err(Error::Config(format!(
                    "marker set `{}`: joint `{name}` has no markers",
                    self.name
                )));
            }
            if !j.cluster.is_empty() && j.cluster.len() < 3 {
                return Err(Error::Config(format!(
                    "marker set `{}`: the cluster of joint `{name}` has {} markers; a rigid fit \
                     needs at least 3",
                    self.name,
                    j.cluster.len()
                )));
            }
        }
        Ok(())
    }

    /// Calibrates the marker set on a static trial (markers in metres, gaps already filled).
    pub fn calibrate(&self, data: &MarkerData, side: ArmSide) -> Result<Calibration> {
        self.check()?;
        let mean = |name: &str| -> Result<Vector3<f64>> {
            let m = data.index(name).ok_or_else(|| {
                Error::invalid(&data.path, format!("static trial has no marker `{name}`"))
            })?;
            let mut acc = Vector3::zeros();
            let mut n = 0usize;
            for t in 0..data.n_frames() {
                if let Some(v) = data.get(m, t) {
                    acc += v;
                    n += 1;
                }
            }
            if n == 0 {
                return Err(Error::invalid(
                    &data.path,
                    format!("static trial: marker `{name}` is never seen"),
                ));
            }
            Ok(acc / n as f64)
        };
        let mut joints = Vec::new();
        for (jname, j) in self.joints() {
            let mut landmark = Vector3::zeros();
            for m in &j.markers {
                landmark += mean(&subst(m, side))?;
            }
            landmark /= j.markers.len() as f64;
            let cluster: Vec<String> = j.cluster.iter().map(|m| subst(m, side)).collect();
            let markers: Vec<String> = j.markers.iter().map(|m| subst(m, side)).collect();
            let reference = cluster
                .iter()
                .map(|m| mean(m))
                .collect::<Result<Vec<_>>>()?;
            joints.push(CalibratedJoint {
                name: jname,
                markers,
                cluster,
                reference,
                landmark,
            });
        }
        let centroid = |v: &[String]| -> Result<Option<Vector3<f64>>> {
            if v.is_empty() {
                return Ok(None);
            }
            let mut acc = Vector3::zeros();
            for m in v {
                acc += mean(&subst(m, side))?;
            }
            Ok(Some(acc / v.len() as f64))
        };
        let right = centroid(&self.heading_right)?;
        let left = centroid(&self.heading_left)?;
        let right_direction = match (right, left) {
            (Some(r), Some(l)) => Some(r - l),
            _ => None,
        };
        Ok(Calibration {
            side,
            joints,
            right_direction,
            has_wrist: self.wrist.is_some(),
        })
    }
}

fn subst(m: &str, side: ArmSide) -> String {
    m.replace("{S}", side.prefix())
}

fn push_unique(v: &mut Vec<String>, s: String) {
    if !v.contains(&s) {
        v.push(s);
    }
}

/// One joint, calibrated.
#[derive(Clone, Debug)]
pub struct CalibratedJoint {
    /// "shoulder", "elbow", "wrist" or "fingertip".
    pub name: &'static str,
    /// Landmark (or direct) markers.
    pub markers: Vec<String>,
    /// Cluster markers (empty: measured directly).
    pub cluster: Vec<String>,
    /// Static-trial positions of the cluster markers.
    pub reference: Vec<Vector3<f64>>,
    /// Static-trial position of the joint centre.
    pub landmark: Vector3<f64>,
}

/// A marker set calibrated on one subject's static trial, for one arm.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The arm.
    pub side: ArmSide,
    /// Shoulder, elbow, (wrist,) fingertip.
    pub joints: Vec<CalibratedJoint>,
    /// Lab-frame direction from the actor's left to right heading markers (static trial).
    pub right_direction: Option<Vector3<f64>>,
    has_wrist: bool,
}

impl Calibration {
    /// Static-trial shoulder landmark (the actor-frame origin).
    pub fn static_shoulder(&self) -> Vector3<f64> {
        self.joints[0].landmark
    }

    /// Reconstructs the joint centres of a movement trial (metres, lab frame; gaps already
    /// filled). Frames at either end where a joint cannot be reconstructed are dropped; such a
    /// frame inside the trial is an error naming the file, the frame and the cluster.
    pub fn reconstruct(&self, data: &MarkerData) -> Result<ArmTrajectory> {
        let n = data.n_frames();
        let nan = Vector3::repeat(f64::NAN);
        let mut out: Vec<Vec<Vector3<f64>>> = vec![vec![nan; n]; self.joints.len()];
        let mut failure: Vec<Option<String>> = vec![None; n];
        for (j, joint) in self.joints.iter().enumerate() {
            if joint.cluster.is_empty() {
                let idx = lookup(data, &joint.markers)?;
                for t in 0..n {
                    let mut acc = Vector3::zeros();
                    let mut ok = true;
                    for &m in &idx {
                        match data.get(m, t) {
                            Some(v) => acc += v,
                            None => ok = false,
                        }
                    }
                    if ok {
                        out[j][t] = acc / idx.len() as f64;
                    } else if failure[t].is_none() {
                        failure[t] = Some(format!(
                            "the {} marker(s) {} are missing",
                            joint.name,
                            joint.markers.join(", ")
                        ));
                    }
                }
                continue;
            }
            let idx = lookup(data, &joint.cluster)?;
            let mut a = Vec::with_capacity(idx.len());
            let mut b = Vec::with_capacity(idx.len());
            for t in 0..n {
                a.clear();
                b.clear();
                for (k, &m) in idx.iter().enumerate() {
                    if let Some(v) = data.get(m, t) {
                        a.push(joint.reference[k]);
                        b.push(v);
                    }
                }
                if a.len() >= 3 {
                    let (rot, trans) = kabsch(&a, &b);
                    out[j][t] = rot * joint.landmark + trans;
                } else if failure[t].is_none() {
                    failure[t] = Some(format!(
                        "the {} cluster ({}) has {} of {} markers; a rigid fit needs at least 3",
                        joint.name,
                        joint.cluster.join(", "),
                        a.len(),
                        joint.cluster.len()
                    ));
                }
            }
        }
        let ok = |t: usize| failure[t].is_none();
        let Some(first) = (0..n).find(|&t| ok(t)) else {
            let why = failure.first().cloned().flatten().unwrap_or_default();
            return Err(Error::invalid(
                &data.path,
                format!("no frame can be reconstructed: {why}"),
            ));
        };
        let last = (0..n).rev().find(|&t| ok(t)).unwrap_or(first);
        if let Some(bad) = (first..=last).find(|&t| !ok(t)) {
            let message = format!(
                "frame {}: {} (gap too long to interpolate; raise max_gap or trim the trial)",
                data.first_frame + bad as i64,
                failure[bad].clone().unwrap_or_default()
            );
            return Err(match data.first_line {
                Some(line) => Error::parse(&data.path, line + bad, message),
                None => Error::invalid(&data.path, message),
            });
        }
        let take = |j: usize| out[j][first..=last].to_vec();
        let last_joint = self.joints.len() - 1;
        Ok(ArmTrajectory {
            rate: data.rate,
            p: take(0),
            q: take(1),
            w: if self.has_wrist {
                take(2)
            } else {
                vec![nan; last - first + 1]
            },
            r: take(last_joint),
        })
    }
}

fn lookup(data: &MarkerData, names: &[String]) -> Result<Vec<usize>> {
    names
        .iter()
        .map(|m| {
            data.index(m)
                .ok_or_else(|| Error::invalid(&data.path, format!("the trial has no marker `{m}`")))
        })
        .collect()
}

/// Least-squares rigid transform (rotation, translation) taking points `a` onto points `b`
/// (Kabsch / Horn via SVD, with the reflection guard so the result is a proper rotation).
pub fn kabsch(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> (Matrix3<f64>, Vector3<f64>) {
    let n = a.len().min(b.len()).max(1) as f64;
    let ca = a.iter().fold(Vector3::zeros(), |s, v| s + v) / n;
    let cb = b.iter().fold(Vector3::zeros(), |s, v| s + v) / n;
    let mut h = Matrix3::zeros();
    for (x, y) in a.iter().zip(b) {
        h += (x - ca) * (y - cb).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return (Matrix3::identity(), cb - ca);
    };
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let rot = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    (rot, cb - rot * ca)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn kabsch_recovers_rotation_and_is_reflection_safe() {
        let a = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.1, 0.0, 0.0),
            Vector3::new(0.0, 0.07, 0.0),
            Vector3::new(0.02, 0.03, 0.05),
        ];
        let rot = Rotation3::from_euler_angles(0.3, -1.1, 2.0).into_inner();
        let t = Vector3::new(0.5, -0.2, 1.0);
        let b: Vec<_> = a.iter().map(|p| rot * p + t).collect();
        let (r, tr) = kabsch(&a, &b);
        assert!((r - rot).norm() < 1e-9);
        assert!((tr - t).norm() < 1e-9);
        // A mirrored target: the best proper rotation, never a reflection.
        let m: Vec<_> = b.iter().map(|p| Vector3::new(-p.x, p.y, p.z)).collect();
        let (r, _) = kabsch(&a, &m);
        assert!((r.determinant() - 1.0).abs() < 1e-9);
    }

    fn synthetic(frames: &[(Matrix3<f64>, Vector3<f64>)], with_landmarks: bool) -> MarkerData {
        // A right arm: clusters around each landmark.
        let mut names = Vec::new();
        let mut pos = Vec::new();
        let base: Vec<(&str, Vector3<f64>)> = vec![
            ("RGTH", Vector3::new(0.2, 0.0, 0.4)),
            ("RLEP", Vector3::new(0.25, 0.0, 0.12)),
            ("RMEP", Vector3::new(0.19, 0.0, 0.12)),
            ("RSPR", Vector3::new(0.24, 0.25, 0.1)),
            ("RSPU", Vector3::new(0.2, 0.25, 0.1)),
            ("RFTP", Vector3::new(0.22, 0.42, 0.1)),
        ];
        let mut add = |name: String, p: Vector3<f64>| {
            names.push(name);
            pos.push(
                frames
                    .iter()
                    .map(|(r, t)| (r * p + t).into())
                    .collect::<Vec<[f64; 3]>>(),
            );
        };
        for (cl, c) in [("SHO", base[0].1), ("UAR", base[1].1), ("LAR", base[3].1)] {
            let offs = [
                Vector3::new(0.03, 0.0, 0.0),
                Vector3::new(0.0, 0.04, 0.0),
                Vector3::new(0.0, 0.0, 0.05),
                Vector3::new(0.02, 0.02, 0.02),
            ];
            for (k, o) in offs.iter().enumerate() {
                add(format!("R{cl}{}", k + 1), c + o);
            }
        }
        for (n, p) in &base {
            if with_landmarks || *n == "RFTP" {
                add((*n).to_string(), *p);
            }
        }
        add("LSHO1".into(), Vector3::new(-0.2, 0.0, 0.4));
        for k in 2..=4 {
            add(
                format!("LSHO{k}"),
                Vector3::new(-0.2, 0.01 * f64::from(k), 0.4),
            );
        }
        MarkerData {
            path: "s.csv".into(),
            rate: 100.0,
            first_frame: 1,
            first_line: None,
            names,
            positions: pos,
        }
    }

    #[test]
    fn reconstructs_rigidly_moved_landmarks() {
        let id = (Matrix3::identity(), Vector3::zeros());
        let static_trial = synthetic(&[id, id], true);
        let cal = MarkerSet::ue_adl()
            .calibrate(&static_trial, ArmSide::Right)
            .unwrap();
        assert!((cal.static_shoulder() - Vector3::new(0.2, 0.0, 0.4)).norm() < 1e-12);
        assert!(cal.right_direction.unwrap().x > 0.3);
        let rot = Rotation3::from_euler_angles(0.1, 0.2, 0.3).into_inner();
        let t = Vector3::new(0.01, 0.02, -0.03);
        let mut moving = synthetic(&[id, (rot, t)], false);
        // Drop one marker of the UAR cluster in frame 2: three remain, still exact.
        let k = moving.index("RUAR2").unwrap();
        moving.positions[k][1] = [f64::NAN; 3];
        let arm = cal.reconstruct(&moving).unwrap();
        let want_q = rot * Vector3::new(0.22, 0.0, 0.12) + t;
        assert!(
            (arm.q[1] - want_q).norm() < 1e-9,
            "{:?} vs {want_q:?}",
            arm.q[1]
        );
        // Two missing in an interior frame: an error naming the frame and the cluster.
        let mut three = synthetic(&[id, (rot, t), id], false);
        let k1 = three.index("RUAR1").unwrap();
        three.positions[k][1] = [f64::NAN; 3];
        three.positions[k1][1] = [f64::NAN; 3];
        let e = cal.reconstruct(&three).unwrap_err().to_string();
        assert!(
            e.contains("s.csv") && e.contains("frame 2") && e.contains("2 of 4"),
            "{e}"
        );
        // A missing landmark in the static trial names the marker.
        let e = MarkerSet::ue_adl()
            .calibrate(&moving, ArmSide::Right)
            .unwrap_err()
            .to_string();
        assert!(e.contains("RGTH"), "{e}");
    }
}
