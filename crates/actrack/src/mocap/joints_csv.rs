//! The joint-trajectory CSV of DESIGN.md (ground truth and tracker output alike).
//!
//! A header line, then one row per frame:
//! `frame,time,action,theta_u,theta_v,px,py,pz,qx,qy,qz,rx,ry,rz` — metres and seconds; columns
//! are found by name, so their order is free and extra columns (a wrist `wx,wy,wz`, posterior
//! columns `p_<action>`, …) are allowed. `time` and the nine pose columns are required; `frame`,
//! `action`, `theta_u`, `theta_v` are optional and may be empty. The sample rate is taken from
//! the mean time step over the whole span.

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::Vector3;

use super::{ArmTrajectory, read_text};
use crate::error::{Error, Result};

/// The content of a joint-trajectory CSV.
#[derive(Clone, Debug)]
pub struct JointsCsv {
    /// The poses (and the wrist if `wx,wy,wz` are present, NaN otherwise).
    pub arm: ArmTrajectory,
    /// Time of each row, seconds.
    pub time: Vec<f64>,
    /// The first non-empty `action` value.
    pub action: Option<String>,
    /// The first non-empty (`theta_u`, `theta_v`).
    pub theta: Option<[f64; 2]>,
}

/// The DESIGN.md header, without extra columns.
pub const HEADER: &str = "frame,time,action,theta_u,theta_v,px,py,pz,qx,qy,qz,rx,ry,rz";

/// `true` when the text starts (after an optional BOM) with a header whose first column is
/// `frame` or `time`: a joint-trajectory CSV rather than a Vicon export.
pub fn looks_like_joints_csv(text: &str) -> bool {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let first = text.lines().next().unwrap_or("");
    let col = first.split(',').next().unwrap_or("").trim();
    (col == "frame" || col == "time") && first.contains("px")
}

/// Reads a joint-trajectory CSV (plain, `.xz` or `.gz`).
pub fn read_joints_csv(path: &Path) -> Result<JointsCsv> {
    parse_joints_csv(path, &read_text(path)?)
}

/// Parses the text of a joint-trajectory CSV; `path` is for messages.
pub fn parse_joints_csv(path: &Path, text: &str) -> Result<JointsCsv> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    let Some((_, header)) = lines.next() else {
        return Err(Error::parse(
            path,
            1,
            "empty file: expected the header line",
        ));
    };
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let find = |name: &str| cols.iter().position(|c| *c == name);
    let need = |name: &str| {
        find(name).ok_or_else(|| {
            Error::parse(
                path,
                1,
                format!("missing column `{name}` (expected a header like `{HEADER}`)"),
            )
        })
    };
    let time_c = need("time")?;
    let pose_c: Vec<usize> = ["px", "py", "pz", "qx", "qy", "qz", "rx", "ry", "rz"]
        .iter()
        .map(|n| need(n))
        .collect::<Result<_>>()?;
    let wrist_c: Option<Vec<usize>> = ["wx", "wy", "wz"].iter().map(|n| find(n)).collect();
    let action_c = find("action");
    let tu_c = find("theta_u");
    let tv_c = find("theta_v");

    let mut out = JointsCsv {
        arm: ArmTrajectory::default(),
        time: Vec::new(),
        action: None,
        theta: None,
    };
    let num = |f: &[&str], c: usize, ln: usize| -> Result<f64> {
        let s = f.get(c).map_or("", |s| s.trim());
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                Error::parse(
                    path,
                    ln,
                    format!("column `{}`: `{s}` is not a finite number", cols[c]),
                )
            })
    };
    for (ln, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != cols.len() {
            return Err(Error::parse(
                path,
                ln,
                format!("row has {} fields, the header {}", f.len(), cols.len()),
            ));
        }
        out.time.push(num(&f, time_c, ln)?);
        let mut v = [0.0; 9];
        for (k, &c) in pose_c.iter().enumerate() {
            v[k] = num(&f, c, ln)?;
        }
        out.arm.p.push(Vector3::new(v[0], v[1], v[2]));
        out.arm.q.push(Vector3::new(v[3], v[4], v[5]));
        out.arm.r.push(Vector3::new(v[6], v[7], v[8]));
        let w = match &wrist_c {
            Some(wc) if wc.iter().all(|&c| !f[c].trim().is_empty()) => Vector3::new(
                num(&f, wc[0], ln)?,
                num(&f, wc[1], ln)?,
                num(&f, wc[2], ln)?,
            ),
            _ => Vector3::repeat(f64::NAN),
        };
        out.arm.w.push(w);
        if out.action.is_none()
            && let Some(c) = action_c
            && !f[c].trim().is_empty()
        {
            out.action = Some(f[c].trim().to_string());
        }
        if out.theta.is_none()
            && let (Some(u), Some(v)) = (tu_c, tv_c)
            && !f[u].trim().is_empty()
            && !f[v].trim().is_empty()
        {
            out.theta = Some([num(&f, u, ln)?, num(&f, v, ln)?]);
        }
    }
    if out.time.len() < 2 {
        return Err(Error::invalid(path, "fewer than 2 data rows"));
    }
    let steps: Vec<f64> = out.time.windows(2).map(|w| w[1] - w[0]).collect();
    if let Some(k) = steps.iter().position(|d| *d <= 0.0) {
        return Err(Error::parse(path, k + 3, "time does not increase"));
    }
    // Mean rate over the whole span: robust to the rounding of individual time stamps.
    let span = out.time[out.time.len() - 1] - out.time[0];
    out.arm.rate = (out.time.len() - 1) as f64 / span;
    Ok(out)
}

/// Formats a trajectory as a joint-trajectory CSV (with `wx,wy,wz` when the wrist is known).
pub fn format_joints_csv(arm: &ArmTrajectory, action: &str, theta: Option<[f64; 2]>) -> String {
    let wrist = arm.w.iter().all(|w| w.x.is_finite()) && arm.w.len() == arm.len();
    let mut s = String::from(HEADER);
    if wrist {
        s.push_str(",wx,wy,wz");
    }
    s.push('\n');
    let (tu, tv) = theta.map_or((String::new(), String::new()), |t| {
        (format!("{:.6}", t[0]), format!("{:.6}", t[1]))
    });
    for t in 0..arm.len() {
        let time = t as f64 / arm.rate;
        let _ = write!(s, "{t},{time:.6},{action},{tu},{tv}");
        for v in [arm.p[t], arm.q[t], arm.r[t]] {
            let _ = write!(s, ",{:.6},{:.6},{:.6}", v.x, v.y, v.z);
        }
        if wrist {
            let v = arm.w[t];
            let _ = write!(s, ",{:.6},{:.6},{:.6}", v.x, v.y, v.z);
        }
        s.push('\n');
    }
    s
}

/// Writes a joint-trajectory CSV atomically (temporary file, then rename).
pub fn write_joints_csv(
    path: &Path,
    arm: &ArmTrajectory,
    action: &str,
    theta: Option<[f64; 2]>,
) -> Result<()> {
    super::write_atomic(path, format_joints_csv(arm, action, theta).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip() {
        let arm = ArmTrajectory {
            rate: 30.0,
            p: vec![Vector3::new(0.0, 0.0, 0.0); 3],
            q: vec![Vector3::new(0.1, 0.2, -0.25); 3],
            w: vec![Vector3::new(0.2, 0.3, -0.3); 3],
            r: (0..3_i32)
                .map(|t| Vector3::new(0.1, 0.4 + 0.01 * f64::from(t), -0.3))
                .collect(),
        };
        let text = format_joints_csv(&arm, "reach", Some([0.1, 0.42]));
        assert!(looks_like_joints_csv(&text));
        let back = parse_joints_csv(Path::new("j.csv"), &text).unwrap();
        assert!((back.arm.rate - 30.0).abs() < 1e-3);
        assert_eq!(back.action.as_deref(), Some("reach"));
        assert_eq!(back.theta, Some([0.1, 0.42]));
        assert!((back.arm.r[2] - arm.r[2]).norm() < 1e-6);
        assert!((back.arm.w[1] - arm.w[1]).norm() < 1e-6);
    }

    #[test]
    fn errors_name_line() {
        let text = format!("{HEADER}\n0,0,a,,,0,0,0,0,0,0,0,0,0\n1,0.1,a,,,0,0,0,x,0,0,0,0,0\n");
        let e = parse_joints_csv(Path::new("j.csv"), &text)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("j.csv:3:") && e.contains("`qx`"), "{e}");
        let e = parse_joints_csv(Path::new("j.csv"), "frame,time\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("j.csv:1:") && e.contains("px"), "{e}");
        let text = format!("{HEADER}\n0,0,a,,,0,0,0,0,0,0,0,0\n");
        let e = parse_joints_csv(Path::new("j.csv"), &text)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("j.csv:2:"), "{e}");
    }
}
