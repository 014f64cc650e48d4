//! One demonstration trial, from file to PHMM input: import, actor frame, θ, trimming,
//! resampling.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use nalgebra::Vector3;
use serde::{Deserialize, Deserializer, Serialize};

use super::actor::{ActorFrame, Heading};
use super::markerset::{Calibration, MarkerSet};
use super::{ArmSide, ArmTrajectory, GapReport, MarkerData};
use crate::error::{Error, Result};

/// How θ of a trial is taken from its fingertip trajectory (actor frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ThetaRule {
    /// Fingertip (x, y) at maximal arm extension `argmax_t ‖r_t − p_t‖` (SPEC §2.2).
    #[default]
    MaxExtension,
    /// Fingertip (x, y) at the last frame.
    LastFrame,
}

/// The coordinates trials are expressed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum CoordinateFrame {
    /// The actor frame of DESIGN.md (origin at the static trial's acting shoulder, table axes):
    /// what action models should be trained in.
    #[default]
    Actor,
    /// The capture's lab frame as recorded (a left arm is still mirrored, x → −x). For
    /// comparison only: subjects sit in different places, so models generalise worse.
    Lab,
}

/// Trimming of the rest phases at onset and offset by fingertip speed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrimOptions {
    /// Speed threshold in m/s: the movement spans from the first to the last frame whose
    /// (50 ms-smoothed) fingertip speed exceeds it.
    pub speed: f64,
    /// Frames of rest kept on either side (at the original rate).
    #[serde(default)]
    pub margin: usize,
}

impl Default for TrimOptions {
    fn default() -> Self {
        TrimOptions {
            speed: 0.05,
            margin: 0,
        }
    }
}

/// How raw captures become PHMM observation sequences. Stored in the model file so that
/// `classify` prepares a trial exactly as `train` did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Preprocessing {
    /// Longest gap (frames) filled by linear interpolation (default 10 = 0.1 s at 100 Hz).
    pub max_gap: usize,
    /// Target frame rate in Hz (the video's); `None` keeps the capture rate.
    #[serde(deserialize_with = "off_or")]
    pub frame_rate: Option<f64>,
    /// Trimming of rest phases; `None` keeps whole trials.
    #[serde(deserialize_with = "off_or")]
    pub trim: Option<TrimOptions>,
    /// Heading of the actor frame.
    pub heading: Heading,
    /// Actor frame (default) or lab frame.
    pub frame: CoordinateFrame,
    /// θ rule for trials without an explicit θ.
    pub theta: ThetaRule,
    /// The marker set (default: UE-ADL).
    pub marker_set: MarkerSet,
}

impl Default for Preprocessing {
    fn default() -> Self {
        Preprocessing {
            max_gap: 10,
            frame_rate: Some(30.0),
            trim: Some(TrimOptions::default()),
            heading: Heading::Auto,
            frame: CoordinateFrame::Actor,
            theta: ThetaRule::MaxExtension,
            marker_set: MarkerSet::ue_adl(),
        }
    }
}

impl Preprocessing {
    /// Checks the options.
    pub fn check(&self) -> Result<()> {
        if let Some(f) = self.frame_rate
            && !(f.is_finite() && f > 0.0)
        {
            return Err(Error::Config(format!(
                "frame_rate must be positive, not {f}"
            )));
        }
        if let Some(t) = self.trim
            && !(t.speed.is_finite() && t.speed >= 0.0)
        {
            return Err(Error::Config(format!(
                "trim speed must be ≥ 0 m/s, not {}",
                t.speed
            )));
        }
        if let Heading::Degrees(d) = self.heading
            && !d.is_finite()
        {
            return Err(Error::Config("heading must be finite".into()));
        }
        self.marker_set.check()
    }
}

/// The message of the error for a marker trial loaded without a static trial.
pub(crate) const NEEDS_STATIC: &str =
    "a marker trial needs its subject's static trial (none given)";

/// One prepared trial.
#[derive(Clone, Debug)]
pub struct Trial {
    /// The movement file.
    pub source: PathBuf,
    /// The acting arm.
    pub arm: ArmSide,
    /// Joint centres in the actor frame, trimmed and resampled: the PHMM input.
    pub arm_trajectory: ArmTrajectory,
    /// θ (actor frame, metres): explicit, or from the rule on the untrimmed capture.
    pub theta: [f64; 2],
    /// Gaps too long to interpolate (markers used by this arm only).
    pub gaps: Vec<GapReport>,
    /// The lab → actor map used.
    pub frame: ActorFrame,
    /// Median upper-arm |q − p| and elbow→fingertip |r − q| lengths over the trial (metres).
    pub arm_lengths: [f64; 2],
    /// Seconds of the recording cut before the first kept frame (rest trimmed at onset).
    pub onset: f64,
    /// Duration of the whole recording (after reconstruction), seconds.
    pub recording_duration: f64,
}

impl Trial {
    /// Number of PHMM frames within the first `fraction` of the *recording* (rest phases
    /// included), at least 2.
    pub fn frames_within_recording(&self, fraction: f64) -> usize {
        let cut = fraction * self.recording_duration - self.onset;
        let n = self.arm_trajectory.len();
        let k = (cut * self.arm_trajectory.rate + 1e-9).floor();
        if k < 1.0 {
            2.min(n)
        } else {
            ((k as usize) + 1).clamp(2.min(n), n)
        }
    }
}

/// Imports trials, caching each static calibration (a subject's 30 trials share one).
#[derive(Debug, Default)]
pub struct Importer {
    /// The preprocessing applied to every trial.
    pub options: Preprocessing,
    cache: Mutex<HashMap<(PathBuf, ArmSide), Arc<Calibration>>>,
}

impl Importer {
    /// An importer with `options` (checked).
    pub fn new(options: Preprocessing) -> Result<Importer> {
        options.check()?;
        Ok(Importer {
            options,
            cache: Mutex::new(HashMap::new()),
        })
    }

    /// The calibration of a static trial for one arm (cached).
    pub fn calibration(&self, static_path: &Path, side: ArmSide) -> Result<Arc<Calibration>> {
        let key = (static_path.to_path_buf(), side);
        if let Some(c) = self.cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
            return Ok(c);
        }
        let wanted = self.options.marker_set.static_markers(side);
        let mut data = read_markers(static_path, &wanted)?;
        data.fill_gaps(self.options.max_gap);
        let cal = Arc::new(self.options.marker_set.calibrate(&data, side)?);
        if let Ok(mut c) = self.cache.lock() {
            c.insert(key, cal.clone());
        }
        Ok(cal)
    }

    /// Loads a movement trial: markers (Vicon CSV, plain/`.xz`/`.gz`, or C3D) with the
    /// subject's static trial, or a joint-trajectory CSV (taken to be in the actor frame already,
    /// a left arm is still mirrored; `static_path` unused). `theta`: an explicit θ, else the
    /// file's `theta_u/theta_v` (joints CSV) or the θ rule.
    pub fn load(
        &self,
        path: &Path,
        static_path: Option<&Path>,
        side: ArmSide,
        theta: Option<[f64; 2]>,
        rule: Option<ThetaRule>,
    ) -> Result<Trial> {
        let rule = rule.unwrap_or(self.options.theta);
        let wanted = self.options.marker_set.movement_markers(side);
        let mut data = match read_source(path, &wanted)? {
            Source::Markers(d) => d,
            Source::Joints(jt) => {
                check_joints_units_and_frame(path, &jt.arm)?;
                let frame = ActorFrame {
                    origin: [0.0; 3],
                    heading_deg: 0.0,
                    mirror: side == ArmSide::Left,
                };
                let arm = if frame.mirror {
                    frame.apply(&jt.arm)
                } else {
                    jt.arm
                };
                let theta = theta
                    .or(jt.theta)
                    .unwrap_or_else(|| theta_by_rule(&arm, rule));
                return self.finish(path, side, arm, theta, Vec::new(), frame);
            }
        };
        let static_path =
            static_path.ok_or_else(|| Error::invalid(path, NEEDS_STATIC.to_string()))?;
        let cal = self.calibration(static_path, side)?;
        let gaps = data.fill_gaps(self.options.max_gap);
        let lab = cal.reconstruct(&data)?;
        let frame = match self.options.frame {
            CoordinateFrame::Actor => ActorFrame::new(
                cal.static_shoulder(),
                side,
                self.options.heading,
                cal.right_direction,
            ),
            CoordinateFrame::Lab => ActorFrame {
                origin: [0.0; 3],
                heading_deg: 0.0,
                mirror: side == ArmSide::Left,
            },
        };
        let arm = frame.apply(&lab);
        let theta = theta.unwrap_or_else(|| theta_by_rule(&arm, rule));
        self.finish(path, side, arm, theta, gaps, frame)
    }

    fn finish(
        &self,
        path: &Path,
        side: ArmSide,
        arm: ArmTrajectory,
        theta: [f64; 2],
        gaps: Vec<GapReport>,
        frame: ActorFrame,
    ) -> Result<Trial> {
        let recording_duration = (arm.len().max(1) - 1) as f64 / arm.rate;
        let (arm, onset) = match self.options.trim {
            Some(t) => {
                let (trimmed, first) = trim_rest_range(&arm, t);
                (trimmed, first as f64 / arm.rate)
            }
            None => (arm, 0.0),
        };
        let arm = match self.options.frame_rate {
            Some(f) => resample(&arm, f),
            None => arm,
        };
        if arm.len() < 2 {
            return Err(Error::invalid(
                path,
                "fewer than 2 frames left after trimming",
            ));
        }
        let arm_lengths = [
            median(
                arm.p
                    .iter()
                    .zip(&arm.q)
                    .map(|(p, q)| (q - p).norm())
                    .collect(),
            ),
            median(
                arm.q
                    .iter()
                    .zip(&arm.r)
                    .map(|(q, r)| (r - q).norm())
                    .collect(),
            ),
        ];
        check_arm_lengths(path, arm_lengths)?;
        Ok(Trial {
            source: path.to_path_buf(),
            arm: side,
            arm_trajectory: arm,
            theta,
            gaps,
            frame,
            arm_lengths,
            onset,
            recording_duration,
        })
    }
}

/// Median upper-arm (shoulder → elbow) and elbow → fingertip lengths of a trajectory, metres
/// (frames with a non-finite joint skipped).
fn median_segment_lengths(arm: &ArmTrajectory) -> [f64; 2] {
    let seg = |a: &[nalgebra::Vector3<f64>], b: &[nalgebra::Vector3<f64>]| {
        median(
            a.iter()
                .zip(b)
                .map(|(x, y)| (y - x).norm())
                .filter(|d| d.is_finite())
                .collect(),
        )
    };
    [seg(&arm.p, &arm.q), seg(&arm.q, &arm.r)]
}

/// Segment lengths (metres) a human arm has: shoulder → elbow and elbow → fingertip.
pub const HUMAN_SEGMENT_RANGE: (f64, f64) = (0.1, 1.0);

/// Refuses arm segments no human has, naming millimetres when the lengths are a thousand
/// times too long.
fn check_arm_lengths(path: &Path, l: [f64; 2]) -> Result<()> {
    let (lo, hi) = HUMAN_SEGMENT_RANGE;
    if l.iter().all(|v| (lo..=hi).contains(v)) {
        return Ok(());
    }
    let hint = if l.iter().all(|v| (lo * 1000.0..=hi * 1000.0).contains(v)) {
        ": the coordinates look like millimetres; actrack reads metres (divide them by 1000)"
    } else if l.iter().all(|v| (lo * 100.0..=hi * 100.0).contains(v)) {
        ": the coordinates look like centimetres; actrack reads metres (divide them by 100)"
    } else {
        ""
    };
    Err(Error::invalid(
        path,
        format!(
            "implausible arm: shoulder → elbow {:.3} and elbow → fingertip {:.3} (median, in the \
             file's units) where a human arm has {lo}–{hi} m per segment{hint}",
            l[0], l[1]
        ),
    ))
}

/// A joint-trajectory CSV must be in metres and in the actor frame (origin at the acting
/// shoulder at rest): refuses millimetres, and a shoulder far from the origin (a world-frame
/// track, such as the ground truth `synth` and `demo` write).
fn check_joints_units_and_frame(path: &Path, arm: &ArmTrajectory) -> Result<()> {
    check_arm_lengths(path, median_segment_lengths(arm))?;
    let mut p: Vec<(f64, nalgebra::Vector3<f64>)> = arm
        .p
        .iter()
        .filter(|v| v.iter().all(|c| c.is_finite()))
        .map(|v| (v.norm(), *v))
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((d, v)) = p.get(p.len() / 2)
        && *d > MAX_SHOULDER_OFFSET
    {
        return Err(Error::invalid(
            path,
            format!(
                "the shoulder is at ({:.2}, {:.2}, {:.2}) m (median), {d:.2} m from the origin: a \
                 joint-trajectory CSV must be in the actor frame (origin at the acting shoulder at \
                 rest, within {MAX_SHOULDER_OFFSET} m); this looks like a world-frame track such \
                 as the truth.csv of `synth` or `demo` (subtract the scene's [actor] origin and \
                 rotate by its heading first)",
                v[0], v[1], v[2]
            ),
        ));
    }
    Ok(())
}

/// How far (metres) the shoulder of a joint-trajectory CSV may lie from the actor-frame origin
/// (the shoulder at rest) in the median frame: trunk lean during a reach moves it by a few
/// centimetres to a couple of decimetres.
pub const MAX_SHOULDER_OFFSET: f64 = 0.35;

/// What a movement file holds.
#[derive(Clone, Debug)]
pub enum Source {
    /// Marker trajectories (Vicon CSV or C3D).
    Markers(MarkerData),
    /// Joint trajectories (the CSV of DESIGN.md).
    Joints(super::joints_csv::JointsCsv),
}

/// Reads a movement file by content: C3D (extension `.c3d` or the 0x50 header key), a
/// joint-trajectory CSV (header starting `frame,` / `time,`), else a Vicon Nexus CSV. Any of the
/// text formats may be xz- or gzip-compressed.
pub fn read_source(path: &Path, wanted: &[String]) -> Result<Source> {
    let raw = std::fs::read(path).map_err(|e| Error::read(path, e))?;
    let is_c3d_ext = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("c3d"));
    if is_c3d_ext || (raw.len() >= 512 && raw[1] == 0x50 && raw[0] != b'T') {
        return super::c3d::parse_c3d(path, &raw, Some(wanted)).map(Source::Markers);
    }
    let bytes = super::decompress(path, raw)?;
    let text = String::from_utf8(bytes).map_err(|e| {
        Error::invalid(
            path,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })?;
    if super::joints_csv::looks_like_joints_csv(&text) {
        super::joints_csv::parse_joints_csv(path, &text).map(Source::Joints)
    } else {
        super::vicon::parse_vicon_csv(path, &text, Some(wanted)).map(Source::Markers)
    }
}

/// Reads marker data (Vicon CSV or C3D) for a static trial.
pub fn read_markers(path: &Path, wanted: &[String]) -> Result<MarkerData> {
    match read_source(path, wanted)? {
        Source::Markers(d) => Ok(d),
        Source::Joints(_) => Err(Error::invalid(
            path,
            "a joint-trajectory CSV cannot serve as a static (marker calibration) trial",
        )),
    }
}

/// θ of a trajectory (actor frame) by `rule`.
pub fn theta_by_rule(arm: &ArmTrajectory, rule: ThetaRule) -> [f64; 2] {
    let n = arm.len();
    if n == 0 {
        return [0.0, 0.0];
    }
    let t = match rule {
        ThetaRule::LastFrame => n - 1,
        ThetaRule::MaxExtension => {
            let mut best = 0;
            let mut best_d = f64::NEG_INFINITY;
            for t in 0..n {
                let d = (arm.r[t] - arm.p[t]).norm();
                if d > best_d {
                    best_d = d;
                    best = t;
                }
            }
            best
        }
    };
    [arm.r[t].x, arm.r[t].y]
}

/// Fingertip speed per frame (m/s): central differences, then a centred moving average over
/// about 50 ms.
pub fn fingertip_speed(arm: &ArmTrajectory) -> Vec<f64> {
    let n = arm.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let raw: Vec<f64> = (0..n)
        .map(|t| {
            let (a, b) = (t.saturating_sub(1), (t + 1).min(n - 1));
            (arm.r[b] - arm.r[a]).norm() * arm.rate / (b - a) as f64
        })
        .collect();
    let half = ((0.025 * arm.rate).round() as usize).max(1);
    (0..n)
        .map(|t| {
            let (a, b) = (t.saturating_sub(half), (t + half).min(n - 1));
            raw[a..=b].iter().sum::<f64>() / (b - a + 1) as f64
        })
        .collect()
}

/// Cuts the rest phases at onset and offset: keeps from the first to the last frame whose
/// fingertip speed exceeds the threshold (plus the margin). A trial that never moves is kept.
pub fn trim_rest(arm: &ArmTrajectory, opts: TrimOptions) -> ArmTrajectory {
    trim_rest_range(arm, opts).0
}

/// [`trim_rest`], also returning the index of the first kept frame.
pub fn trim_rest_range(arm: &ArmTrajectory, opts: TrimOptions) -> (ArmTrajectory, usize) {
    let v = fingertip_speed(arm);
    let Some(first) = v.iter().position(|&s| s > opts.speed) else {
        return (arm.clone(), 0);
    };
    let last = v.iter().rposition(|&s| s > opts.speed).unwrap_or(first);
    let a = first.saturating_sub(opts.margin);
    let b = (last + opts.margin).min(arm.len() - 1);
    (arm.slice(a..b + 1), a)
}

/// Linear resampling to `rate` Hz, from the first frame to the last whole sample.
pub fn resample(arm: &ArmTrajectory, rate: f64) -> ArmTrajectory {
    let n = arm.len();
    if n == 0 || (rate - arm.rate).abs() < 1e-12 {
        return ArmTrajectory {
            rate,
            ..arm.clone()
        };
    }
    let duration = (n - 1) as f64 / arm.rate;
    let m = (duration * rate + 1e-9).floor() as usize + 1;
    let lerp = |v: &Vec<Vector3<f64>>, s: f64| {
        let i = (s.floor() as usize).min(n - 1);
        let j = (i + 1).min(n - 1);
        let f = s - i as f64;
        v[i] * (1.0 - f) + v[j] * f
    };
    let mut out = ArmTrajectory {
        rate,
        ..ArmTrajectory::default()
    };
    for k in 0..m {
        let s = k as f64 / rate * arm.rate;
        out.p.push(lerp(&arm.p, s));
        out.q.push(lerp(&arm.q, s));
        out.w.push(lerp(&arm.w, s));
        out.r.push(lerp(&arm.r, s));
    }
    out
}

/// Median of a list (NaNs sort last; empty → NaN).
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Deserialises an optional value that may also be written as `false` (off) or a keyword.
pub(crate) fn off_or<'de, D, T>(d: D) -> std::result::Result<Option<T>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum OffOr<T> {
        Flag(bool),
        Word(String),
        Value(T),
    }
    match Option::<OffOr<T>>::deserialize(d)? {
        None | Some(OffOr::Flag(false)) => Ok(None),
        Some(OffOr::Value(v)) => Ok(Some(v)),
        Some(OffOr::Flag(true)) => Err(serde::de::Error::custom(
            "`true` is not a value here: give the settings or `false`",
        )),
        Some(OffOr::Word(w)) if w == "capture" || w == "off" || w == "none" => Ok(None),
        Some(OffOr::Word(w)) => Err(serde::de::Error::custom(format!("unexpected `{w}`"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(n: usize, rate: f64) -> ArmTrajectory {
        let v = |t: usize| Vector3::new(t as f64, 0.0, 0.0);
        ArmTrajectory {
            rate,
            p: (0..n).map(|_| Vector3::zeros()).collect(),
            q: (0..n).map(v).collect(),
            w: (0..n).map(v).collect(),
            r: (0..n).map(|t| v(t) * 2.0).collect(),
        }
    }

    #[test]
    fn resample_100_to_30() {
        let a = line(101, 100.0); // 1 s
        let b = resample(&a, 30.0);
        assert_eq!(b.len(), 31);
        assert!((b.q[3].x - 10.0).abs() < 1e-9);
        assert!((b.q[30].x - 100.0).abs() < 1e-9);
        assert!((b.r[1].x - 2.0 * 100.0 / 30.0).abs() < 1e-9);
    }

    #[test]
    fn theta_rules_and_trim() {
        let mut a = line(50, 100.0);
        // Rest (no motion) for the first 10 and last 10 frames.
        for t in 0..50 {
            let x = (t.clamp(10, 39) as f64) * 0.01;
            a.r[t] = Vector3::new(x, 0.5 - (x - 0.2).abs(), 0.0);
        }
        let ext = theta_by_rule(&a, ThetaRule::MaxExtension);
        let last = theta_by_rule(&a, ThetaRule::LastFrame);
        assert!((last[0] - 0.39).abs() < 1e-12);
        assert!((ext[0] - 0.2).abs() < 1e-12 && (ext[1] - 0.5).abs() < 1e-12);
        let tr = trim_rest(
            &a,
            TrimOptions {
                speed: 0.05,
                margin: 0,
            },
        );
        assert!(tr.len() < 40 && tr.len() > 25, "{}", tr.len());
        assert!((median(vec![3.0, 1.0, 2.0]) - 2.0).abs() < 1e-12);
    }
}
