//! The trajectory CSV of DESIGN.md, as the tracker writes it and as `eval` reads both it and the
//! ground truth.
//!
//! Header, then one row per frame:
//! `frame,time,action,theta_u,theta_v,px,py,pz,qx,qy,qz,rx,ry,rz` — frame index, seconds, action
//! name (empty when none), θ in the actor frame (metres), shoulder p, elbow q, fingertip r in
//! **world** coordinates (metres). The tracker's output adds `p_<action>…` (the action posterior),
//! `theta_u_std,theta_v_std` (metres), `entropy` (histogram entropy of θ in [0, 1]) and `ess`.
//! The reader finds columns by name, so extra columns are ignored.

use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};

/// The base columns shared by ground truth and tracker output.
pub const BASE_COLUMNS: [&str; 14] = [
    "frame", "time", "action", "theta_u", "theta_v", "px", "py", "pz", "qx", "qy", "qz", "rx",
    "ry", "rz",
];

/// One row of a trajectory CSV.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajRow {
    /// Frame index.
    pub frame: usize,
    /// Time in seconds.
    pub time: f64,
    /// Action name (empty for none).
    pub action: String,
    /// θ (actor frame, metres); NaN when unknown.
    pub theta: [f64; 2],
    /// Shoulder, elbow, fingertip (world, metres).
    pub pose: [f64; 9],
    /// Tracker output only: the action posterior, in the order of [`Trajectory::actions`].
    pub posterior: Vec<f64>,
    /// Tracker output only: per-component std of θ (metres).
    pub theta_std: Option<[f64; 2]>,
    /// Tracker output only: histogram entropy of θ in [0, 1].
    pub entropy: Option<f64>,
    /// Tracker output only: effective sample size.
    pub ess: Option<f64>,
}

impl TrajRow {
    /// A ground-truth row.
    pub fn truth(frame: usize, time: f64, action: &str, theta: [f64; 2], pose: [f64; 9]) -> Self {
        Self {
            frame,
            time,
            action: action.into(),
            theta,
            pose,
            posterior: Vec::new(),
            theta_std: None,
            entropy: None,
            ess: None,
        }
    }
}

/// A trajectory CSV in memory.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// Names of the posterior columns (`p_<name>`); empty for ground truth.
    pub actions: Vec<String>,
    /// The rows, in file order.
    pub rows: Vec<TrajRow>,
}

fn fmt(x: f64) -> String {
    if x.is_nan() {
        String::new()
    } else {
        format!("{x:.6}")
    }
}

impl Trajectory {
    /// `true` when the rows carry tracker columns.
    pub fn is_track(&self) -> bool {
        self.rows.first().is_some_and(|r| r.theta_std.is_some())
    }

    /// Writes the CSV to `out`.
    pub fn write_to<W: Write>(&self, mut out: W) -> std::io::Result<()> {
        let track = self.is_track();
        write_header(&mut out, &self.actions, track)?;
        for r in &self.rows {
            write_row(&mut out, r, track)?;
        }
        out.flush()
    }

    /// Writes the CSV to `path` (through a temporary file renamed into place).
    pub fn save(&self, path: &Path) -> Result<()> {
        self.save_with_comment(path, "")
    }

    /// Writes the CSV to `path` with `comment` (lines starting with `#`, such as
    /// [`crate::TrackConfig::to_comment`]) before the header.
    pub fn save_with_comment(&self, path: &Path, comment: &str) -> Result<()> {
        let tmp = temp_path(path);
        let file = std::fs::File::create(&tmp).map_err(|e| Error::write(path, e))?;
        let mut guard = TempGuard::new(&tmp);
        let mut out = std::io::BufWriter::new(file);
        out.write_all(comment.as_bytes())
            .and_then(|()| self.write_to(out))
            .map_err(|e| Error::write(path, e))?;
        std::fs::rename(&tmp, path).map_err(|e| Error::write(path, e))?;
        guard.keep();
        Ok(())
    }

    /// Reads a trajectory CSV (ground truth or tracker output).
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
        Self::parse(&text, path)
    }

    /// Parses CSV text; `path` is used in messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
        let Some((_, header)) = lines.next() else {
            return Err(Error::invalid(path, "empty file: expected a header line"));
        };
        let cols: Vec<&str> = header.split(',').map(str::trim).collect();
        let find = |name: &str| cols.iter().position(|c| *c == name);
        let mut base = [0usize; 14];
        for (k, name) in BASE_COLUMNS.iter().enumerate() {
            base[k] = find(name)
                .ok_or_else(|| Error::parse(path, 1, format!("missing column `{name}`")))?;
        }
        let post: Vec<(String, usize)> = cols
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.strip_prefix("p_").map(|a| (a.to_string(), i)))
            .collect();
        let extra = ["theta_u_std", "theta_v_std", "entropy", "ess"].map(find);
        let mut rows = Vec::new();
        for (ln, line) in lines {
            let f: Vec<&str> = line.split(',').map(str::trim).collect();
            if f.len() < cols.len() {
                return Err(Error::parse(
                    path,
                    ln + 1,
                    format!("{} fields, the header has {}", f.len(), cols.len()),
                ));
            }
            let num = |i: usize| -> Result<f64> {
                if f[i].is_empty() {
                    return Ok(f64::NAN);
                }
                f[i].parse::<f64>().map_err(|_| {
                    Error::parse(
                        path,
                        ln + 1,
                        format!("column `{}`: `{}` is not a number", cols[i], f[i]),
                    )
                })
            };
            let frame = f[base[0]].parse::<usize>().map_err(|_| {
                Error::parse(
                    path,
                    ln + 1,
                    format!("column `frame`: `{}` is not a frame index", f[base[0]]),
                )
            })?;
            let mut pose = [0.0; 9];
            for j in 0..9 {
                pose[j] = num(base[5 + j])?;
                if !pose[j].is_finite() {
                    return Err(Error::parse(
                        path,
                        ln + 1,
                        format!(
                            "column `{}`: `{}` is not a finite coordinate (every pose column \
                             needs a number)",
                            cols[base[5 + j]],
                            f[base[5 + j]]
                        ),
                    ));
                }
            }
            let posterior = post
                .iter()
                .map(|(_, i)| num(*i))
                .collect::<Result<Vec<_>>>()?;
            let opt = |i: Option<usize>| -> Result<Option<f64>> { i.map(num).transpose() };
            let (su, sv) = (opt(extra[0])?, opt(extra[1])?);
            rows.push(TrajRow {
                frame,
                time: num(base[1])?,
                action: f[base[2]].to_string(),
                theta: [num(base[3])?, num(base[4])?],
                pose,
                posterior,
                theta_std: su.zip(sv).map(|(a, b)| [a, b]),
                entropy: opt(extra[2])?,
                ess: opt(extra[3])?,
            });
        }
        Ok(Self {
            actions: post.into_iter().map(|(a, _)| a).collect(),
            rows,
        })
    }
}

/// A tracker-output CSV written row by row: a temporary file beside `path`, renamed into place by
/// [`finish`](Self::finish) (removed if it is dropped before), so that tracking a long video
/// needs no memory per frame. The bytes are those of [`Trajectory::save_with_comment`].
pub struct TrajectoryWriter {
    path: std::path::PathBuf,
    tmp: std::path::PathBuf,
    out: std::io::BufWriter<std::fs::File>,
    guard: TempGuard,
}

impl TrajectoryWriter {
    /// Starts `path`: `comment` (lines starting with `#`), then the header of a tracker output
    /// with the posterior columns of `actions`.
    ///
    /// # Errors
    /// When the temporary file cannot be created or written.
    pub fn create(path: &Path, comment: &str, actions: &[String]) -> Result<Self> {
        let tmp = temp_path(path);
        let file = std::fs::File::create(&tmp).map_err(|e| Error::write(path, e))?;
        let guard = TempGuard::new(&tmp);
        let mut out = std::io::BufWriter::new(file);
        out.write_all(comment.as_bytes())
            .and_then(|()| write_header(&mut out, actions, true))
            .map_err(|e| Error::write(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            tmp,
            out,
            guard,
        })
    }

    /// Appends one row.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn push(&mut self, row: &TrajRow) -> Result<()> {
        write_row(&mut self.out, row, true).map_err(|e| Error::write(&self.path, e))
    }

    /// Flushes the file and renames it into place.
    ///
    /// # Errors
    /// When the file cannot be written or renamed.
    pub fn finish(mut self) -> Result<()> {
        self.out.flush().map_err(|e| Error::write(&self.path, e))?;
        std::fs::rename(&self.tmp, &self.path).map_err(|e| Error::write(&self.path, e))?;
        self.guard.keep();
        Ok(())
    }
}

fn write_header<W: Write>(out: &mut W, actions: &[String], track: bool) -> std::io::Result<()> {
    let mut header: Vec<String> = BASE_COLUMNS.iter().map(|s| (*s).to_string()).collect();
    if track {
        header.extend(actions.iter().map(|a| format!("p_{a}")));
        header.extend(["theta_u_std", "theta_v_std", "entropy", "ess"].map(String::from));
    }
    writeln!(out, "{}", header.join(","))
}

fn write_row<W: Write>(out: &mut W, r: &TrajRow, track: bool) -> std::io::Result<()> {
    let mut f = vec![
        r.frame.to_string(),
        format!("{:.6}", r.time),
        r.action.clone(),
        fmt(r.theta[0]),
        fmt(r.theta[1]),
    ];
    f.extend(r.pose.iter().map(|x| fmt(*x)));
    if track {
        f.extend(r.posterior.iter().map(|x| fmt(*x)));
        let s = r.theta_std.unwrap_or([f64::NAN; 2]);
        f.extend([
            fmt(s[0]),
            fmt(s[1]),
            fmt(r.entropy.unwrap_or(f64::NAN)),
            fmt(r.ess.unwrap_or(f64::NAN)),
        ]);
    }
    writeln!(out, "{}", f.join(","))
}

/// Removes a temporary file when dropped, unless [`TempGuard::keep`] was called (after the
/// file was renamed into place): no error path leaves a `.name.tmp-<pid>` behind.
#[derive(Debug)]
pub struct TempGuard {
    path: Option<std::path::PathBuf>,
}

impl TempGuard {
    /// Guards `path`.
    pub fn new(path: &Path) -> Self {
        Self {
            path: Some(path.to_path_buf()),
        }
    }

    /// The file is in place: do not remove it.
    pub fn keep(&mut self) {
        self.path = None;
    }
}

impl Drop for TempGuard {
    fn drop(&mut self) {
        if let Some(p) = self.path.take() {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// `dir/.name.tmp-<pid>` beside `path`, for writing then renaming into place.
pub fn temp_path(path: &Path) -> std::path::PathBuf {
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

#[cfg(test)]
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_track_and_truth() {
        let mut t = Trajectory {
            actions: vec!["point".into(), "push".into()],
            rows: Vec::new(),
        };
        for k in 0..3 {
            t.rows.push(TrajRow {
                frame: k,
                time: k as f64 / 30.0,
                action: "point".into(),
                theta: [0.1, 0.5],
                pose: [k as f64, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.25],
                posterior: vec![0.75, 0.25],
                theta_std: Some([0.01, 0.02]),
                entropy: Some(0.5),
                ess: Some(100.0),
            });
        }
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("t.csv");
        t.save(&p).unwrap();
        let back = Trajectory::load(&p).unwrap();
        assert_eq!(back.actions, t.actions);
        assert_eq!(back.rows.len(), 3);
        assert!((back.rows[2].time - t.rows[2].time).abs() < 1e-6);
        assert_eq!(back.rows[1].pose, t.rows[1].pose);
        let truth = Trajectory {
            actions: vec![],
            rows: vec![TrajRow::truth(0, 0.0, "", [f64::NAN; 2], [0.0; 9])],
        };
        truth.save(&p).unwrap();
        let back = Trajectory::load(&p).unwrap();
        assert!(
            !back.is_track() && back.rows[0].theta[0].is_nan() && back.rows[0].action.is_empty()
        );
        std::fs::write(&p, "frame,time\n").unwrap();
        assert!(
            Trajectory::load(&p)
                .unwrap_err()
                .to_string()
                .contains("missing column `action`")
        );
        std::fs::write(
            &p,
            format!("{}\n0,0,a,x,0,0,0,0,0,0,0,0,0,0\n", BASE_COLUMNS.join(",")),
        )
        .unwrap();
        let e = Trajectory::load(&p).unwrap_err().to_string();
        assert!(e.contains(":2:") && e.contains("theta_u"), "{e}");
    }
}
