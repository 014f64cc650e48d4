//! Vicon Nexus "Trajectories" CSV export (plain, `.xz` or `.gz`).
//!
//! Layout (Vicon Nexus 2.x): a line `Trajectories`, the sample rate, the marker names
//! (`Subject:MARKER`) in every third column from the third, a line `Frame,Sub Frame,X,Y,Z,…`, a
//! units line (`mm`), then one row per frame. A missing sample is an empty field. A UTF-8
//! byte-order mark and a leading `Devices` section are tolerated; the data ends at the first
//! empty line or at the end of the file.
//!
//! Only the markers that are asked for are parsed (the rest of each row is only counted), which
//! halves the import time of a 49-marker export when one arm is wanted.

use std::path::Path;

use super::{MarkerData, read_text};
use crate::error::{Error, Result};

/// Reads a Vicon Nexus trajectories CSV (plain, `.xz` or `.gz`, detected from the content).
///
/// `wanted`: the marker names (without the `Subject:` prefix) to keep; `None` keeps all. A wanted
/// name that the file does not have is an error naming the file and the marker.
pub fn read_vicon_csv(path: &Path, wanted: Option<&[String]>) -> Result<MarkerData> {
    let text = read_text(path)?;
    parse_vicon_csv(path, &text, wanted)
}

/// Parses the text of a Vicon Nexus trajectories CSV; `path` is used in error messages only.
pub fn parse_vicon_csv(path: &Path, text: &str, wanted: Option<&[String]>) -> Result<MarkerData> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));

    // Section header, skipping any other section (e.g. `Devices`) before it.
    let mut found = false;
    for (_, line) in lines.by_ref() {
        if first_field(line).trim() == "Trajectories" {
            found = true;
            break;
        }
    }
    if !found {
        return Err(Error::parse(
            path,
            1,
            "not a Vicon Nexus trajectories export: no line `Trajectories`",
        ));
    }
    let mut next = |what: &str| {
        lines.next().ok_or_else(|| {
            Error::invalid(
                path,
                format!("file ends before the {what} line of the header"),
            )
        })
    };

    let (ln, rate_line) = next("sample-rate")?;
    let rate: f64 = first_field(rate_line)
        .trim()
        .parse()
        .ok()
        .filter(|r: &f64| r.is_finite() && *r > 0.0)
        .ok_or_else(|| {
            Error::parse(
                path,
                ln,
                format!("expected the sample rate in Hz, found `{rate_line}`"),
            )
        })?;

    let (names_ln, names_line) = next("marker-name")?;
    let name_fields: Vec<&str> = names_line.split(',').collect();
    let mut names = Vec::new();
    let mut columns = Vec::new();
    for (c, f) in name_fields.iter().enumerate() {
        let f = f.trim();
        if f.is_empty() {
            continue;
        }
        if c < 2 || (c - 2) % 3 != 0 {
            return Err(Error::parse(
                path,
                names_ln,
                format!(
                    "marker name `{f}` in column {} (expected columns 3, 6, 9, …)",
                    c + 1
                ),
            ));
        }
        let expected = 2 + 3 * names.len();
        if c != expected {
            return Err(Error::parse(
                path,
                names_ln,
                format!(
                    "marker name `{f}` in column {} but column {} has none (every marker's \
                     three columns carry its name in the first)",
                    c + 1,
                    expected + 1
                ),
            ));
        }
        let name = f.rsplit(':').next().unwrap_or(f).to_string();
        names.push(name);
        columns.push(c);
    }
    if names.is_empty() {
        return Err(Error::parse(
            path,
            names_ln,
            "no marker names on the marker-name line",
        ));
    }
    let n_fields = 2 + 3 * names.len();

    let (ln, axes_line) = next("`Frame,Sub Frame,X,Y,Z` column")?;
    let axes: Vec<&str> = axes_line.split(',').map(str::trim).collect();
    if axes.first().copied() != Some("Frame") {
        return Err(Error::parse(
            path,
            ln,
            format!(
                "expected the column line `Frame,Sub Frame,X,Y,Z,…`, found `{}`",
                truncate(axes_line)
            ),
        ));
    }
    for (k, &c) in columns.iter().enumerate() {
        let ok = ["X", "Y", "Z"]
            .iter()
            .enumerate()
            .all(|(j, a)| axes.get(c + j) == Some(a));
        if !ok {
            return Err(Error::parse(
                path,
                ln,
                format!("columns of marker `{}` are not labelled X, Y, Z", names[k]),
            ));
        }
    }

    let (ln, units_line) = next("units")?;
    let unit = units_line
        .split(',')
        .map(str::trim)
        .find(|f| !f.is_empty())
        .unwrap_or("mm");
    let scale = match unit {
        "mm" => 1e-3,
        "cm" => 1e-2,
        "m" => 1.0,
        other => {
            return Err(Error::parse(
                path,
                ln,
                format!("unknown length unit `{other}` (expected mm, cm or m)"),
            ));
        }
    };

    // Which markers to keep.
    let keep: Vec<usize> = match wanted {
        None => (0..names.len()).collect(),
        Some(w) => {
            let mut keep = Vec::with_capacity(w.len());
            for name in w {
                let k = names.iter().position(|n| n == name).ok_or_else(|| {
                    Error::parse(
                        path,
                        names_ln,
                        format!(
                            "marker `{name}` is not in this file (it has: {})",
                            names.join(", ")
                        ),
                    )
                })?;
                keep.push(k);
            }
            keep
        }
    };
    let kept_names: Vec<String> = keep.iter().map(|&k| names[k].clone()).collect();
    // Column of each kept marker's X, and for each field index the kept slot it fills.
    let mut slot_of_field = vec![usize::MAX; n_fields];
    for (s, &k) in keep.iter().enumerate() {
        slot_of_field[columns[k]] = s;
    }

    let mut positions: Vec<Vec<[f64; 3]>> = vec![Vec::new(); keep.len()];
    let mut first_frame = None;
    let mut first_line = None;
    let mut prev_frame: Option<i64> = None;
    let mut row = vec![[f64::NAN; 3]; keep.len()];
    for (ln, line) in lines {
        if line.trim().is_empty() {
            break;
        }
        row.fill([f64::NAN; 3]);
        let mut fields = line.split(',');
        let frame_field = fields.next().unwrap_or("");
        let frame: i64 = frame_field.trim().parse().map_err(|_| {
            Error::parse(
                path,
                ln,
                format!("frame number `{frame_field}` is not an integer"),
            )
        })?;
        if let Some(p) = prev_frame
            && frame != p + 1
        {
            return Err(Error::parse(
                path,
                ln,
                format!("frame {frame} follows frame {p} (frames must be consecutive)"),
            ));
        }
        prev_frame = Some(frame);
        first_frame.get_or_insert(frame);
        first_line.get_or_insert(ln);
        let mut count = 1;
        let mut c = 1;
        while let Some(f) = fields.next() {
            count += 1;
            if c >= 2 && c < n_fields && slot_of_field[c] != usize::MAX {
                let s = slot_of_field[c];
                let y = fields.next();
                let z = fields.next();
                count += usize::from(y.is_some()) + usize::from(z.is_some());
                let (Some(y), Some(z)) = (y, z) else { break };
                row[s] = parse_xyz(path, ln, &kept_names[s], [f, y, z], scale)?;
                c += 3;
            } else {
                c += 1;
            }
        }
        if count != n_fields {
            return Err(Error::parse(
                path,
                ln,
                format!(
                    "row has {count} fields, expected {n_fields} (2 + 3 × {} markers)",
                    names.len()
                ),
            ));
        }
        for (s, v) in row.iter().enumerate() {
            positions[s].push(*v);
        }
    }
    let Some(first_frame) = first_frame else {
        return Err(Error::invalid(path, "no data rows after the header"));
    };
    Ok(MarkerData {
        path: path.to_path_buf(),
        rate,
        first_frame,
        first_line,
        names: kept_names,
        positions,
    })
}

fn parse_xyz(path: &Path, ln: usize, marker: &str, f: [&str; 3], scale: f64) -> Result<[f64; 3]> {
    let t = [f[0].trim(), f[1].trim(), f[2].trim()];
    let empty = t.iter().filter(|s| s.is_empty()).count();
    if empty == 3 {
        return Ok([f64::NAN; 3]);
    }
    if empty != 0 {
        return Err(Error::parse(
            path,
            ln,
            format!("marker `{marker}` has only some of its X, Y, Z values"),
        ));
    }
    let mut out = [0.0; 3];
    for (o, s) in out.iter_mut().zip(t) {
        let v: f64 = s
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| {
                Error::parse(
                    path,
                    ln,
                    format!(
                        "marker `{marker}`: `{}` is not a finite number",
                        truncate(s)
                    ),
                )
            })?;
        *o = v * scale;
    }
    Ok(out)
}

fn first_field(line: &str) -> &str {
    line.split(',').next().unwrap_or("")
}

fn truncate(s: &str) -> String {
    if s.chars().count() > 40 {
        let mut t: String = s.chars().take(40).collect();
        t.push('…');
        t
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fmt::Write as _;

    pub(crate) fn sample() -> String {
        let mut s = String::from(
            "\u{feff}Trajectories\n100\n,,S:A,,,S:B,,\nFrame,Sub Frame,X,Y,Z,X,Y,Z\n,,mm,mm,mm,mm,mm,mm\n",
        );
        for f in 1..=5 {
            let b = if f == 3 {
                ",,".to_string()
            } else {
                format!("{f},0,0")
            };
            let _ = writeln!(s, "{f},0,{f}000,0,0,{b}");
        }
        s.push('\n');
        s
    }

    #[test]
    fn parses_sample() {
        let d = parse_vicon_csv(Path::new("x.csv"), &sample(), None).unwrap();
        assert_eq!(d.names, ["A", "B"]);
        assert!((d.rate - 100.0).abs() < 1e-12);
        assert_eq!(d.first_frame, 1);
        assert_eq!(d.positions[0].len(), 5);
        assert!((d.positions[0][1][0] - 2.0).abs() < 1e-12);
        assert!(d.positions[1][2][0].is_nan());
        assert!((d.positions[1][3][0] - 0.004).abs() < 1e-12);
    }

    #[test]
    fn wanted_subset_and_unknown_marker() {
        let d = parse_vicon_csv(Path::new("x.csv"), &sample(), Some(&["B".to_string()])).unwrap();
        assert_eq!(d.names, ["B"]);
        let e = parse_vicon_csv(Path::new("x.csv"), &sample(), Some(&["Q".to_string()]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.csv:3") && e.contains("`Q`"), "{e}");
    }

    /// Fuzzing found a marker name past an unnamed marker's columns indexing beyond the row.
    #[test]
    fn marker_name_after_a_gap_is_an_error() {
        let gap = sample().replace(",,S:A,,,S:B,,", ",,,,,S:B,,");
        let e = parse_vicon_csv(Path::new("x.csv"), &gap, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("x.csv:3:") && e.contains("column 6") && e.contains("column 3"),
            "{e}"
        );
    }

    #[test]
    fn errors_name_line() {
        let bad = sample().replace("4,0,4000", "4,0,4x00");
        let e = parse_vicon_csv(Path::new("x.csv"), &bad, None)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:9:"), "{e}");
        let ragged = sample().replace("2,0,2000,0,0,2,0,0", "2,0,2000,0,0,2,0");
        let e = parse_vicon_csv(Path::new("x.csv"), &ragged, None)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:7:") && e.contains("fields"), "{e}");
        let nohdr = sample().replace("Frame,Sub Frame", "Fr,Sub Frame");
        let e = parse_vicon_csv(Path::new("x.csv"), &nohdr, None)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.csv:4:"), "{e}");
        let e = parse_vicon_csv(Path::new("x.csv"), "hello\n", None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("Trajectories"), "{e}");
    }
}
