//! Motion-capture importers: marker trajectories in, arm trajectories in the actor frame out.
//!
//! The chain, from a file to what the action models are trained on:
//!
//! 1. **Markers** ([`MarkerData`]): [`vicon::read_vicon_csv`] (Vicon Nexus CSV, plain/`.xz`/`.gz`)
//!    or [`c3d::read_c3d`]; units converted to metres; short gaps interpolated
//!    ([`MarkerData::fill_gaps`]), long gaps reported ([`GapReport`]).
//! 2. **Joint centres** ([`markerset`]): anatomical landmarks calibrated on the static trial in
//!    the frame of their technical marker cluster and carried into every movement frame by a
//!    least-squares rigid fit (Kabsch); the marker set is configuration ([`markerset::MarkerSet`])
//!    with a built-in UE-ADL preset. The result is an [`ArmTrajectory`] (shoulder p, elbow q,
//!    wrist w, fingertip r per frame) in the lab frame.
//! 3. **Actor frame** ([`actor`]): origin at the acting shoulder landmark of the static trial,
//!    axes of the table (the lab's, turned about z when the subject faces another way), a left
//!    arm mirrored onto the right (x → −x).
//! 4. **Preprocessing** ([`trial`]): resampling to the video's frame rate, trimming rest phases
//!    by fingertip speed, θ per trial (fingertip table-plane position at maximal extension, at
//!    the last frame, or given).
//!
//! Joint trajectories can also be read and written directly in the trajectory CSV of DESIGN.md
//! ([`joints_csv`]).

pub mod actor;
pub mod c3d;
pub mod glob;
pub mod joints_csv;
pub mod markerset;
pub mod trial;
pub mod vicon;

use std::io::Read;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Marker trajectories of one capture, in metres (lab frame). A missing sample is NaN.
#[derive(Clone, Debug)]
pub struct MarkerData {
    /// The file they were read from (for messages).
    pub path: PathBuf,
    /// Sample rate in Hz.
    pub rate: f64,
    /// Frame number of the first row (as in the file).
    pub first_frame: i64,
    /// 1-based line of the first data row in a text file (Vicon CSV; rows follow line by
    /// line), `None` for binary files (C3D). Messages about a frame name this line.
    pub first_line: Option<usize>,
    /// Marker names without any `Subject:` prefix.
    pub names: Vec<String>,
    /// `positions[marker][frame]`, metres; NaN where the marker was not seen.
    pub positions: Vec<Vec<[f64; 3]>>,
}

/// The gaps of one marker that were too long to interpolate.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GapReport {
    /// The marker.
    pub marker: String,
    /// Inclusive ranges of file frame numbers without data.
    pub ranges: Vec<(i64, i64)>,
}

impl MarkerData {
    /// Number of frames.
    pub fn n_frames(&self) -> usize {
        self.positions.first().map_or(0, Vec::len)
    }

    /// Index of a marker by name.
    pub fn index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Position of marker `m` at frame index `t`, if seen.
    pub fn get(&self, m: usize, t: usize) -> Option<Vector3<f64>> {
        let p = self.positions.get(m)?.get(t)?;
        if p[0].is_nan() {
            None
        } else {
            Some(Vector3::new(p[0], p[1], p[2]))
        }
    }

    /// Fills interior gaps of at most `max_gap` frames by linear interpolation and returns the
    /// gaps left (longer gaps and gaps at either end), per marker with file frame numbers.
    pub fn fill_gaps(&mut self, max_gap: usize) -> Vec<GapReport> {
        let mut reports = Vec::new();
        for (m, track) in self.positions.iter_mut().enumerate() {
            let n = track.len();
            let mut ranges = Vec::new();
            let mut t = 0;
            while t < n {
                if !track[t][0].is_nan() {
                    t += 1;
                    continue;
                }
                let start = t;
                while t < n && track[t][0].is_nan() {
                    t += 1;
                }
                let len = t - start;
                if start > 0 && t < n && len <= max_gap {
                    let a = track[start - 1];
                    let b = track[t];
                    for k in start..t {
                        let s = (k + 1 - start) as f64 / (len + 1) as f64;
                        track[k] = [0, 1, 2].map(|c| a[c] + s * (b[c] - a[c]));
                    }
                } else {
                    ranges.push((
                        self.first_frame + start as i64,
                        self.first_frame + t as i64 - 1,
                    ));
                }
            }
            if !ranges.is_empty() {
                reports.push(GapReport {
                    marker: self.names[m].clone(),
                    ranges,
                });
            }
        }
        reports
    }
}

/// Which arm performs the action.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ArmSide {
    /// The right arm (marker prefix `R`).
    #[serde(rename = "R", alias = "right")]
    Right,
    /// The left arm (marker prefix `L`), mirrored onto the right in the actor frame.
    #[serde(rename = "L", alias = "left")]
    Left,
}

impl ArmSide {
    /// The marker-name prefix, `"R"` or `"L"`.
    pub fn prefix(self) -> &'static str {
        match self {
            ArmSide::Right => "R",
            ArmSide::Left => "L",
        }
    }
}

impl std::str::FromStr for ArmSide {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "R" | "r" | "right" => Ok(ArmSide::Right),
            "L" | "l" | "left" => Ok(ArmSide::Left),
            _ => Err(format!("arm must be R or L, not `{s}`")),
        }
    }
}

/// Joint centres of one arm over time: shoulder p, elbow q, wrist w, fingertip r (metres).
///
/// A missing joint is NaN (only before [`ArmTrajectory::require_complete`]).
#[derive(Clone, Debug, Default)]
pub struct ArmTrajectory {
    /// Sample rate in Hz.
    pub rate: f64,
    /// Shoulder per frame.
    pub p: Vec<Vector3<f64>>,
    /// Elbow per frame.
    pub q: Vec<Vector3<f64>>,
    /// Wrist per frame (NaN where the data has none).
    pub w: Vec<Vector3<f64>>,
    /// Fingertip per frame.
    pub r: Vec<Vector3<f64>>,
}

impl ArmTrajectory {
    /// Number of frames.
    pub fn len(&self) -> usize {
        self.p.len()
    }

    /// `true` without frames.
    pub fn is_empty(&self) -> bool {
        self.p.is_empty()
    }

    /// Pose of frame `t` as `[p, q, r]` (9 numbers).
    pub fn pose(&self, t: usize) -> [f64; 9] {
        let (p, q, r) = (self.p[t], self.q[t], self.r[t]);
        [p.x, p.y, p.z, q.x, q.y, q.z, r.x, r.y, r.z]
    }

    /// The poses as a T × 9 matrix (one row per frame), the PHMM observation layout.
    pub fn to_matrix(&self) -> nalgebra::DMatrix<f64> {
        nalgebra::DMatrix::from_fn(self.len(), 9, |t, c| {
            let v = match c / 3 {
                0 => self.p[t],
                1 => self.q[t],
                _ => self.r[t],
            };
            v[c % 3]
        })
    }

    /// Frames `range` only.
    #[must_use]
    pub fn slice(&self, range: std::ops::Range<usize>) -> ArmTrajectory {
        ArmTrajectory {
            rate: self.rate,
            p: self.p[range.clone()].to_vec(),
            q: self.q[range.clone()].to_vec(),
            w: self.w[range.clone()].to_vec(),
            r: self.r[range].to_vec(),
        }
    }

    /// Drops leading and trailing frames where p, q or r is missing; any missing joint left
    /// inside is an error naming `path` and the (0-based) frame index.
    pub fn require_complete(&mut self, path: &Path) -> Result<()> {
        let ok = |t: usize| {
            self.p[t].x.is_finite() && self.q[t].x.is_finite() && self.r[t].x.is_finite()
        };
        let n = self.len();
        let Some(first) = (0..n).find(|&t| ok(t)) else {
            return Err(Error::invalid(
                path,
                "no frame has all of shoulder, elbow and fingertip",
            ));
        };
        let last = (0..n).rev().find(|&t| ok(t)).unwrap_or(first);
        if let Some(bad) = (first..=last).find(|&t| !ok(t)) {
            return Err(Error::invalid(
                path,
                format!(
                    "frame index {bad}: a joint cannot be reconstructed (a cluster has fewer than \
                     3 markers there and the gap is too long to interpolate)"
                ),
            ));
        }
        *self = self.slice(first..last + 1);
        Ok(())
    }
}

/// Writes `bytes` to `path` atomically: first to a temporary name beside it, then a rename, so a
/// failed write never leaves a half-written file under the final name.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    let tmp = path.with_file_name(format!(".{name}.tmp{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::write(path, e)
    })
}

/// Reads a whole file, decompressing xz or gzip (detected from the magic bytes), as UTF-8 text.
pub fn read_text(path: &Path) -> Result<String> {
    let raw = std::fs::read(path).map_err(|e| Error::read(path, e))?;
    let bytes = decompress(path, raw)?;
    String::from_utf8(bytes).map_err(|e| {
        Error::invalid(
            path,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

/// Decompresses xz or gzip content (by magic bytes); anything else is returned unchanged.
pub fn decompress(path: &Path, raw: Vec<u8>) -> Result<Vec<u8>> {
    if raw.starts_with(&[0xFD, b'7', b'z', b'X', b'Z', 0x00]) {
        let mut out = Vec::with_capacity(raw.len() * 4);
        lzma_rs::xz_decompress(&mut std::io::Cursor::new(&raw), &mut out)
            .map_err(|e| Error::invalid(path, format!("corrupt xz data: {e}")))?;
        Ok(out)
    } else if raw.starts_with(&[0x1F, 0x8B]) {
        let mut out = Vec::with_capacity(raw.len() * 4);
        flate2::read::MultiGzDecoder::new(&raw[..])
            .read_to_end(&mut out)
            .map_err(|e| Error::invalid(path, format!("corrupt gzip data: {e}")))?;
        Ok(out)
    } else {
        Ok(raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_fill_short_and_report_long() {
        let nan = [f64::NAN; 3];
        let mut d = MarkerData {
            path: "x".into(),
            rate: 100.0,
            first_frame: 10,
            first_line: None,
            names: vec!["A".into()],
            positions: vec![vec![
                nan,
                [0.0; 3],
                nan,
                nan,
                [3.0, 0.0, 0.0],
                nan,
                nan,
                nan,
                [0.0; 3],
            ]],
        };
        let rep = d.fill_gaps(2);
        assert!((d.positions[0][2][0] - 1.0).abs() < 1e-12);
        assert!((d.positions[0][3][0] - 2.0).abs() < 1e-12);
        assert!(d.positions[0][6][0].is_nan());
        assert_eq!(
            rep,
            vec![GapReport {
                marker: "A".into(),
                ranges: vec![(10, 10), (15, 17)]
            }]
        );
    }

    #[test]
    fn gzip_roundtrip() {
        use std::io::Write;
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(b"hello").unwrap();
        let gz = e.finish().unwrap();
        assert_eq!(decompress(Path::new("x"), gz).unwrap(), b"hello");
        assert!(decompress(Path::new("x"), vec![0xFD, b'7', b'z', b'X', b'Z', 0, 1]).is_err());
    }
}
