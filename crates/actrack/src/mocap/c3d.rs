//! C3D (the binary exchange format of Vicon, Qualisys and OptiTrack) through the `c3dio` crate.
//!
//! The points' labels are the marker names (a `Subject:` prefix is dropped), `POINT:UNITS` gives
//! the length unit (mm, cm or m) and `POINT:RATE` the sample rate; a point with a negative
//! residual is missing. The joint mapping is the same [`super::markerset::MarkerSet`] as for
//! Vicon CSV exports.
//!
//! `c3dio` may panic on some malformed files; the parse runs under `catch_unwind` so a damaged
//! file is an error, never a crash.

use std::path::Path;

use super::MarkerData;
use crate::error::{Error, Result};

/// Reads the marker trajectories of a C3D file. `wanted`: the markers to keep (`None`: all);
/// a wanted marker that the file lacks is an error naming it.
pub fn read_c3d(path: &Path, wanted: Option<&[String]>) -> Result<MarkerData> {
    let bytes = std::fs::read(path).map_err(|e| Error::read(path, e))?;
    parse_c3d(path, &bytes, wanted)
}

/// Parses C3D bytes; `path` is for messages.
pub fn parse_c3d(path: &Path, bytes: &[u8], wanted: Option<&[String]>) -> Result<MarkerData> {
    // Cheap structural checks before handing the bytes to c3dio: a 512-byte header whose second
    // byte is the C3D key 0x50 and a parameter block that exists.
    if bytes.len() < 512 || bytes[1] != 0x50 {
        return Err(Error::invalid(
            path,
            "not a C3D file (no 0x50 key in the header)",
        ));
    }
    let param_block = usize::from(bytes[0]);
    if param_block == 0 || param_block * 512 > bytes.len() {
        return Err(Error::invalid(
            path,
            "truncated C3D file (no parameter section)",
        ));
    }
    let owned = bytes.to_vec();
    let parsed = std::panic::catch_unwind(move || {
        c3dio::C3d::from_bytes(&owned).map_err(|e| format!("{e:?}"))
    })
    .map_err(|_| Error::invalid(path, "malformed C3D file (the C3D parser gave up)"))?
    .map_err(|e| Error::invalid(path, format!("malformed C3D file: {e}")))?;
    let points = &parsed.points;
    let unit: String = points
        .units
        .iter()
        .collect::<String>()
        .trim()
        .to_lowercase();
    let scale = match unit.as_str() {
        "mm" | "" => 1e-3,
        "cm" => 1e-2,
        "m" => 1.0,
        other => {
            return Err(Error::invalid(
                path,
                format!("unknown POINT:UNITS `{other}`"),
            ));
        }
    };
    let rate = f64::from(points.frame_rate);
    if !(rate.is_finite() && rate > 0.0) {
        return Err(Error::invalid(path, format!("invalid POINT:RATE {rate}")));
    }
    let (n_frames, n_points) = points.size();
    let names: Vec<String> = (0..n_points)
        .map(|k| {
            let l = points.labels.get(k).map_or("", |s| s.trim());
            l.rsplit(':').next().unwrap_or(l).to_string()
        })
        .collect();
    let keep: Vec<usize> = match wanted {
        None => (0..n_points).collect(),
        Some(w) => w
            .iter()
            .map(|m| {
                names.iter().position(|n| n == m).ok_or_else(|| {
                    Error::invalid(
                        path,
                        format!("marker `{m}` is not among the C3D point labels"),
                    )
                })
            })
            .collect::<Result<_>>()?,
    };
    let mut positions = vec![Vec::with_capacity(n_frames); keep.len()];
    for t in 0..n_frames {
        for (s, &k) in keep.iter().enumerate() {
            let v = match points.get(t, k) {
                Some(mp) if mp.residual >= 0.0 && mp.point.iter().all(|c| c.is_finite()) => {
                    mp.point.map(|c| f64::from(c) * scale)
                }
                _ => [f64::NAN; 3],
            };
            positions[s].push(v);
        }
    }
    if n_frames == 0 {
        return Err(Error::invalid(path, "the C3D file has no frames"));
    }
    Ok(MarkerData {
        path: path.to_path_buf(),
        rate,
        first_frame: i64::from(points.first_frame),
        first_line: None,
        names: keep.iter().map(|&k| names[k].clone()).collect(),
        positions,
    })
}
