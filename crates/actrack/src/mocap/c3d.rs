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
    // The data section must start after the parameter section; c3dio underflows on a data start
    // block of 0 or 1. Header words are little-endian except on MIPS (processor byte 86).
    let processor = bytes.get((param_block - 1) * 512 + 3).copied();
    let word = |i: usize| {
        let b = [bytes[2 * i], bytes[2 * i + 1]];
        if processor == Some(86) {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    };
    let data_block = word(8);
    // The frame range: c3dio overflows when the last frame precedes the first, and allocates
    // frames × markers cells before it reads them, so the data section must be able to hold
    // them (at least 8 bytes a cell: four 16-bit integers).
    let (markers, first, last) = (word(1), word(3), word(4));
    if last < first {
        return Err(Error::invalid(
            path,
            format!("malformed C3D header: the last frame ({last}) precedes the first ({first})"),
        ));
    }
    let cells = (usize::from(last - first) + 1) * usize::from(markers);
    if cells.saturating_mul(8) > bytes.len() {
        return Err(Error::invalid(
            path,
            format!(
                "truncated C3D file: the header promises {} frames of {markers} markers, more \
                 than its {} bytes can hold",
                usize::from(last - first) + 1,
                bytes.len()
            ),
        ));
    }
    if usize::from(data_block) <= param_block {
        return Err(Error::invalid(
            path,
            format!(
                "malformed C3D header: the data section (block {data_block}) must start after \
                 the parameter section (block {param_block})"
            ),
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
    // c3dio quietly reads only the whole frames present when the data section is short; a file
    // cut short is an error, not a shorter trial.
    let promised = usize::from(points.last_frame)
        .checked_sub(usize::from(points.first_frame))
        .map_or(0, |d| d + 1);
    if n_frames < promised {
        return Err(Error::invalid(
            path,
            format!(
                "truncated C3D file: the header promises {promised} frames ({}–{}), the data \
                 section holds {n_frames}",
                points.first_frame, points.last_frame
            ),
        ));
    }
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

#[cfg(test)]
mod tests {
    //! A small C3D *writer* (tests only) following the public C3D format description: 512-byte
    //! blocks; a header block (parameter-block pointer and the 0x50 key, point count, first and
    //! last frame, a negative scale for float data, the data-start block, the frame rate); a
    //! parameter section (header `[1, 0x50, blocks, 84 = Intel]`, then the POINT group and its
    //! parameters, each record pointing to the next with a byte offset); float point data
    //! x, y, z, residual per point and frame, little-endian. It is checked against `c3dio` by
    //! reading real UE-ADL trials back through the importer.

    use std::path::{Path, PathBuf};

    use super::parse_c3d;
    use crate::mocap::trial::{Importer, Preprocessing, read_markers};
    use crate::mocap::{ArmSide, MarkerData};

    /// A parameter value: 16-bit integer, float, one string or a fixed-width string array.
    enum Value<'a> {
        Int(i16),
        Float(f32),
        Chars(&'a str),
        Strings(&'a [String]),
    }

    /// One parameter record: name length, group id, name, offset to the next record (counted
    /// from the offset word), element type (-1 char, 2 int16, 4 float), dimensions, data, an
    /// empty description.
    fn parameter(out: &mut Vec<u8>, group: i8, name: &str, value: &Value<'_>) {
        let (kind, dims, data): (i8, Vec<u8>, Vec<u8>) = match value {
            Value::Int(v) => (2, vec![], v.to_le_bytes().to_vec()),
            Value::Float(v) => (4, vec![], v.to_le_bytes().to_vec()),
            Value::Chars(s) => (-1, vec![s.len() as u8], s.as_bytes().to_vec()),
            Value::Strings(list) => {
                let width = list.iter().map(String::len).max().unwrap_or(1).max(1);
                let mut d = Vec::new();
                for s in *list {
                    d.extend(format!("{s:<width$}").bytes());
                }
                (-1, vec![width as u8, list.len() as u8], d)
            }
        };
        out.push(name.len() as u8);
        out.push(group as u8);
        out.extend(name.bytes());
        let offset = 2 + 1 + 1 + dims.len() + data.len() + 1;
        out.extend((offset as u16).to_le_bytes());
        out.push(kind as u8);
        out.push(dims.len() as u8);
        out.extend(&dims);
        out.extend(&data);
        out.push(0); // description length
    }

    /// A C3D file with the points `labels` (unit `units`, rate `rate`), frames numbered from
    /// `first_frame`; `frames[t][k]` is point k at frame t, `None` = missing (residual −1).
    fn write_c3d(
        labels: &[String],
        units: &str,
        rate: f32,
        first_frame: u16,
        frames: &[Vec<Option<[f32; 3]>>],
    ) -> Vec<u8> {
        let n_points = labels.len();
        let last_frame = first_frame + frames.len() as u16 - 1;
        // Parameter section: the 4-byte header, the POINT group (id 1), its parameters. The data
        // start depends on the section's length, so lay it out once with a placeholder.
        let section = |data_start: i16| {
            let mut p = vec![1u8, 0x50, 0, 84];
            p.push(5);
            p.push((-1i8) as u8);
            p.extend(b"POINT");
            p.extend(3u16.to_le_bytes()); // offset word + description length byte
            p.push(0);
            parameter(&mut p, 1, "USED", &Value::Int(n_points as i16));
            parameter(&mut p, 1, "LABELS", &Value::Strings(labels));
            parameter(&mut p, 1, "SCALE", &Value::Float(-1.0));
            parameter(&mut p, 1, "RATE", &Value::Float(rate));
            parameter(&mut p, 1, "FRAMES", &Value::Int(frames.len() as i16));
            parameter(&mut p, 1, "UNITS", &Value::Chars(units));
            parameter(&mut p, 1, "DATA_START", &Value::Int(data_start));
            // The last record points at zero bytes: group id 0 ends the section.
            let blocks = (p.len() + 2).div_ceil(512);
            p.resize(blocks * 512, 0);
            p[2] = blocks as u8;
            p
        };
        let blocks = section(0).len() / 512;
        let data_start = 2 + blocks as u16;
        let params = section(data_start as i16);
        let mut header = vec![0u8; 512];
        header[0] = 2; // the parameter section starts at block 2
        header[1] = 0x50;
        let mut word =
            |i: usize, v: u16| header[2 * i..2 * i + 2].copy_from_slice(&v.to_le_bytes());
        word(1, n_points as u16);
        word(2, 0); // analog measurements per frame
        word(3, first_frame);
        word(4, last_frame);
        word(5, 0); // maximum interpolation gap
        word(8, data_start);
        word(9, 0); // analog samples per frame
        header[12..16].copy_from_slice(&(-1.0f32).to_le_bytes());
        header[20..24].copy_from_slice(&rate.to_le_bytes());
        let mut out = header;
        out.extend(params);
        for frame in frames {
            assert_eq!(frame.len(), n_points);
            for point in frame {
                // The residual word as a float: camera mask (high byte) and residual (low byte);
                // −1 marks an invalid point.
                let (xyz, residual) = match point {
                    Some(v) => (*v, f32::from((0x0c_i16 << 8) | 2)),
                    None => ([0.0; 3], -1.0),
                };
                for c in xyz {
                    out.extend(c.to_le_bytes());
                }
                out.extend(residual.to_le_bytes());
            }
        }
        let len = out.len().div_ceil(512) * 512;
        out.resize(len, 0);
        out
    }

    /// The markers of `data` as a C3D file in millimetres, labels prefixed `subject:`.
    fn markers_to_c3d(data: &MarkerData, subject: &str) -> Vec<u8> {
        let labels: Vec<String> = data
            .names
            .iter()
            .map(|n| format!("{subject}:{n}"))
            .collect();
        let frames: Vec<Vec<Option<[f32; 3]>>> = (0..data.n_frames())
            .map(|t| {
                data.positions
                    .iter()
                    .map(|m| {
                        let v = m[t];
                        v.iter()
                            .all(|c| c.is_finite())
                            .then(|| v.map(|c| (c * 1000.0) as f32))
                    })
                    .collect()
            })
            .collect();
        let first = u16::try_from(data.first_frame).expect("first frame fits the C3D header");
        write_c3d(&labels, "mm", data.rate as f32, first, &frames)
    }

    fn ue_adl() -> Option<PathBuf> {
        let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/ue-adl");
        if d.is_dir() {
            Some(d)
        } else {
            eprintln!("skipped: {} is absent", d.display());
            None
        }
    }

    fn union(a: Vec<String>, b: Vec<String>) -> Vec<String> {
        let mut out = a;
        for m in b {
            if !out.contains(&m) {
                out.push(m);
            }
        }
        out
    }

    /// A real UE-ADL trial (static + movement, Vicon CSV) rewritten as C3D with the same
    /// markers imports to the same joint trajectories, θ and arm lengths, for both arms.
    #[test]
    fn ue_adl_trial_as_c3d_imports_like_the_csv() {
        let Some(root) = ue_adl() else { return };
        let dir = root.join("ADL001");
        let static_csv = dir.join("ADL001_static.csv.xz");
        let tmp = tempfile::tempdir().expect("temporary directory");
        let pre = Preprocessing::default();
        let set = &pre.marker_set;
        let static_markers = union(
            set.static_markers(ArmSide::Right),
            set.static_markers(ArmSide::Left),
        );
        let static_c3d = tmp.path().join("ADL001_static.c3d");
        let data = read_markers(&static_csv, &static_markers).expect("static CSV");
        std::fs::write(&static_c3d, markers_to_c3d(&data, "ADL001")).expect("write static C3D");
        for (name, side) in [("ADL001FR1", ArmSide::Right), ("ADL001AL1", ArmSide::Left)] {
            let csv = dir.join(format!("{name}.csv.xz"));
            let movement = union(
                set.movement_markers(ArmSide::Right),
                set.movement_markers(ArmSide::Left),
            );
            let data = read_markers(&csv, &movement).expect("movement CSV");
            let c3d = tmp.path().join(format!("{name}.c3d"));
            std::fs::write(&c3d, markers_to_c3d(&data, "ADL001")).expect("write C3D");
            let from_csv = Importer::new(pre.clone())
                .expect("importer")
                .load(&csv, Some(&static_csv), side, None, None)
                .expect("CSV import");
            let from_c3d = Importer::new(pre.clone())
                .expect("importer")
                .load(&c3d, Some(&static_c3d), side, None, None)
                .expect("C3D import");
            let (a, b) = (&from_csv.arm_trajectory, &from_c3d.arm_trajectory);
            assert!(a.len() > 30, "{name}: {} frames", a.len());
            assert_eq!(a.len(), b.len(), "{name}: frame count");
            assert!((a.rate - b.rate).abs() < 1e-9, "{name}: rate");
            let mut worst = 0.0f64;
            for t in 0..a.len() {
                for (x, y) in [(&a.p, &b.p), (&a.q, &b.q), (&a.w, &b.w), (&a.r, &b.r)] {
                    worst = worst.max((x[t] - y[t]).norm());
                }
            }
            assert!(worst < 1e-6, "{name}: joints differ by {worst:e} m");
            for k in 0..2 {
                assert!(
                    (from_csv.theta[k] - from_c3d.theta[k]).abs() < 1e-6,
                    "{name}: θ"
                );
                assert!(
                    (from_csv.arm_lengths[k] - from_c3d.arm_lengths[k]).abs() < 1e-6,
                    "{name}: arm lengths"
                );
            }
            let (fa, fb) = (&from_csv.frame, &from_c3d.frame);
            assert_eq!(
                (fa.heading_deg, fa.mirror),
                (fb.heading_deg, fb.mirror),
                "{name}: actor frame"
            );
            for k in 0..3 {
                assert!((fa.origin[k] - fb.origin[k]).abs() < 1e-6, "{name}: origin");
            }
            println!("{name}: {} frames, joints agree to {worst:.1e} m", a.len());
        }
    }

    /// Labels map to markers by name (subject prefix dropped, any order, a subset), units are
    /// converted, a negative residual is a gap, header fields arrive, and a wanted marker the
    /// file lacks is an error naming it and the file.
    #[test]
    fn c3d_marker_mapping() {
        let labels: Vec<String> = ["S:A", "S:B", "C"].map(String::from).to_vec();
        let frames: Vec<Vec<Option<[f32; 3]>>> = (0..4)
            .map(|t| {
                let f = t as f32;
                vec![
                    Some([1.0 + f, 2.0, 3.0]),
                    (t != 2).then_some([10.0, 20.0 + f, 30.0]),
                    Some([-5.0, 0.5, 7.0 * f]),
                ]
            })
            .collect();
        let bytes = write_c3d(&labels, "cm", 120.0, 7, &frames);
        let path = Path::new("mapping.c3d");
        let all = parse_c3d(path, &bytes, None).expect("parse");
        assert_eq!(all.names, ["A", "B", "C"]);
        assert!((all.rate - 120.0).abs() < 1e-9);
        assert_eq!(all.first_frame, 7);
        assert_eq!(all.n_frames(), 4);
        let wanted = ["C".to_string(), "A".to_string(), "B".to_string()];
        let d = parse_c3d(path, &bytes, Some(&wanted)).expect("parse subset");
        assert_eq!(d.names, ["C", "A", "B"]);
        for t in 0..4 {
            let f = t as f64;
            let close =
                |v: [f64; 3], w: [f64; 3]| v.iter().zip(&w).all(|(a, b)| (a - b).abs() < 1e-7);
            assert!(
                close(d.positions[0][t], [-0.05, 0.005, 0.07 * f]),
                "C at {t}"
            );
            assert!(
                close(d.positions[1][t], [0.01 + 0.01 * f, 0.02, 0.03]),
                "A at {t}"
            );
            if t == 2 {
                assert!(
                    d.positions[2][t].iter().all(|c| c.is_nan()),
                    "B missing at 2"
                );
            } else {
                assert!(
                    close(d.positions[2][t], [0.1, 0.2 + 0.01 * f, 0.3]),
                    "B at {t}"
                );
            }
        }
        let mm = write_c3d(&labels, "mm", 120.0, 1, &frames);
        let d = parse_c3d(path, &mm, None).expect("parse mm");
        assert!((d.positions[0][0][0] - 0.001).abs() < 1e-9);
        let missing = ["A".to_string(), "RFTP".to_string()];
        let e = parse_c3d(path, &bytes, Some(&missing)).expect_err("missing marker");
        let msg = e.to_string();
        assert!(msg.contains("mapping.c3d") && msg.contains("RFTP"), "{msg}");
        let inches = write_c3d(&labels, "in", 120.0, 1, &frames);
        let msg = parse_c3d(path, &inches, None)
            .expect_err("unit")
            .to_string();
        assert!(
            msg.contains("mapping.c3d") && msg.contains("UNITS"),
            "{msg}"
        );
    }

    /// A C3D file cut short (in the data, in the parameter section, in the header) is an error
    /// naming the file, never a shorter trial or a panic.
    #[test]
    fn truncated_c3d_is_an_error_naming_the_file() {
        let labels: Vec<String> = (0..6).map(|k| format!("M{k}")).collect();
        let frames: Vec<Vec<Option<[f32; 3]>>> = (0..200)
            .map(|t| vec![Some([t as f32, 1.0, 2.0]); 6])
            .collect();
        let bytes = write_c3d(&labels, "mm", 100.0, 1, &frames);
        let tmp = tempfile::tempdir().expect("temporary directory");
        let whole = tmp.path().join("whole.c3d");
        std::fs::write(&whole, &bytes).expect("write");
        assert_eq!(
            super::read_c3d(&whole, None)
                .expect("whole file")
                .n_frames(),
            200
        );
        for cut in [bytes.len() / 2, 1024 + 100, 1024, 700, 300] {
            let path = tmp.path().join(format!("cut{cut}.c3d"));
            std::fs::write(&path, &bytes[..cut]).expect("write");
            let msg = super::read_c3d(&path, None)
                .expect_err("truncated file accepted")
                .to_string();
            assert!(msg.contains(&format!("cut{cut}.c3d")), "{cut}: {msg}");
            // The importer's content sniffing gives the same error.
            let e = crate::mocap::trial::read_source(&path, &labels[..2]);
            assert!(e.is_err(), "{cut}: read_source accepted it");
        }
    }

    /// Fuzzing found c3dio underflowing on a data start block at or before the parameters.
    #[test]
    fn data_section_before_parameters_is_an_error() {
        let labels = vec!["M0".to_string()];
        let frames = vec![vec![Some([0.0_f32, 1.0, 2.0])]; 3];
        let good = write_c3d(&labels, "mm", 100.0, 1, &frames);
        for block in [0_u16, 1, 2] {
            let mut bytes = good.clone();
            bytes[16..18].copy_from_slice(&block.to_le_bytes());
            let msg = super::parse_c3d(Path::new("bad.c3d"), &bytes, None)
                .expect_err("accepted")
                .to_string();
            assert!(msg.contains("bad.c3d"), "{block}: {msg}");
        }
    }

    /// The fuzzers' C3D crash inputs (c3dio overflows: an i8 group-id counter, a parameter's
    /// dimension product; a frame range that we check first): each is refused with an error
    /// naming the file, never a panic.
    #[test]
    fn fuzz_seeds_are_errors_not_panics() {
        for (name, bytes) in [
            (
                "group_id_127.c3d",
                &include_bytes!("../../../../fuzz/corpus/c3d/group_id_127.c3d")[..],
            ),
            (
                "last_frame_before_first.c3d",
                &include_bytes!("../../../../fuzz/corpus/c3d/last_frame_before_first.c3d")[..],
            ),
            (
                "dimension_product_overflow.c3d",
                &include_bytes!("../../../../fuzz/corpus/c3d/dimension_product_overflow.c3d")[..],
            ),
        ] {
            let msg = super::parse_c3d(Path::new(name), bytes, None)
                .expect_err("accepted")
                .to_string();
            assert!(msg.contains(name), "{msg}");
        }
    }

    /// The frame range of the header is checked before c3dio allocates or subtracts with it
    /// (fuzz crashes: last frame before the first, and frames × markers beyond the file).
    #[test]
    fn frame_range_beyond_reason_is_an_error() {
        let labels = vec!["M0".to_string()];
        let frames = vec![vec![Some([0.0_f32, 1.0, 2.0])]; 3];
        let good = write_c3d(&labels, "mm", 100.0, 1, &frames);
        let set = |b: &mut Vec<u8>, word: usize, v: u16| {
            b[2 * word..2 * word + 2].copy_from_slice(&v.to_le_bytes());
        };
        let mut back = good.clone();
        set(&mut back, 3, u16::MAX);
        set(&mut back, 4, 1);
        let msg = super::parse_c3d(Path::new("back.c3d"), &back, None)
            .expect_err("accepted")
            .to_string();
        assert!(
            msg.contains("back.c3d") && msg.contains("precedes"),
            "{msg}"
        );
        let mut huge = good;
        set(&mut huge, 1, u16::MAX);
        set(&mut huge, 3, 1);
        set(&mut huge, 4, u16::MAX);
        let msg = super::parse_c3d(Path::new("huge.c3d"), &huge, None)
            .expect_err("accepted")
            .to_string();
        assert!(
            msg.contains("huge.c3d") && msg.contains("more than its"),
            "{msg}"
        );
    }
}
