//! Evaluation plots as PNG (plotters, bitmap backend):
//! * `posterior.png` — the action posterior over time, with the ground-truth action as a band
//!   along the bottom (the paper's Fig. 5);
//! * `theta.png` — θ̄ (u and v) with its ±1 std band and the truth (Fig. 1);
//! * `fingertip.png` — the fingertip estimate against the truth, x, y, z (Fig. 4).
//!
//! Text needs a system font (plotters' `ttf` feature; DejaVu on Debian). When text cannot be
//! drawn (no font found), the plot is drawn again without any text rather than failing.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::prelude::*;

use crate::error::{Error, Result};
use crate::track_csv::Trajectory;

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

const PALETTE: [RGBColor; 6] = [
    RGBColor(230, 76, 51),
    RGBColor(51, 153, 230),
    RGBColor(76, 204, 76),
    RGBColor(230, 178, 25),
    RGBColor(178, 76, 204),
    RGBColor(102, 102, 102),
];

/// Writes the three plots into `dir`; returns their paths.
pub fn write_all(track: &Trajectory, truth: &Trajectory, dir: &Path) -> Result<Vec<PathBuf>> {
    type Plot = fn(&Path, &Trajectory, &Trajectory, bool) -> DrawResult;
    std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
    let mut out = Vec::new();
    let plots: [(&str, Plot); 3] = [
        ("posterior.png", posterior),
        ("theta.png", theta),
        ("fingertip.png", fingertip),
    ];
    for (name, f) in plots {
        let p = dir.join(name);
        if f(&p, track, truth, true).is_err() {
            f(&p, track, truth, false)
                .map_err(|e| Error::write(&p, std::io::Error::other(e.to_string())))?;
        }
        out.push(p);
    }
    Ok(out)
}

fn truth_by_frame(truth: &Trajectory) -> BTreeMap<usize, &crate::track_csv::TrajRow> {
    truth.rows.iter().map(|r| (r.frame, r)).collect()
}

fn x_range(track: &Trajectory) -> std::ops::Range<f64> {
    let last = track.rows.last().map_or(1.0, |r| r.frame as f64);
    0.0..last.max(1.0)
}

fn posterior(path: &Path, track: &Trajectory, truth: &Trajectory, text: bool) -> DrawResult {
    let root = BitMapBackend::new(path, (900, 360)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut b = ChartBuilder::on(&root);
    b.margin(12);
    if text {
        b.caption("Action posterior P(a | I_1:t)", ("sans-serif", 20))
            .x_label_area_size(35)
            .y_label_area_size(45);
    }
    let mut chart = b.build_cartesian_2d(x_range(track), -0.08..1.02)?;
    if text {
        chart
            .configure_mesh()
            .x_desc("frame")
            .y_desc("probability")
            .draw()?;
    }
    let tb = truth_by_frame(truth);
    for r in &track.rows {
        if let Some(t) = tb.get(&r.frame)
            && let Some(i) = track.actions.iter().position(|a| *a == t.action)
        {
            let x = r.frame as f64;
            chart.draw_series(std::iter::once(Rectangle::new(
                [(x - 0.5, -0.07), (x + 0.5, -0.02)],
                PALETTE[i % 6].filled(),
            )))?;
        }
    }
    for (i, a) in track.actions.iter().enumerate() {
        let pts: Vec<(f64, f64)> = track
            .rows
            .iter()
            .filter_map(|r| r.posterior.get(i).map(|p| (r.frame as f64, *p)))
            .collect();
        let s = chart.draw_series(LineSeries::new(pts, PALETTE[i % 6].stroke_width(2)))?;
        if text {
            let c = PALETTE[i % 6];
            s.label(a.clone()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2))
            });
        }
    }
    if text {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

fn theta(path: &Path, track: &Trajectory, truth: &Trajectory, text: bool) -> DrawResult {
    let root = BitMapBackend::new(path, (900, 520)).into_drawing_area();
    root.fill(&WHITE)?;
    let halves = root.split_evenly((2, 1));
    let tb = truth_by_frame(truth);
    for (c, area) in halves.iter().enumerate() {
        let est: Vec<(f64, f64, f64)> = track
            .rows
            .iter()
            .map(|r| {
                (
                    r.frame as f64,
                    r.theta[c] * 100.0,
                    r.theta_std.map_or(0.0, |s| s[c]) * 100.0,
                )
            })
            .filter(|p| p.1.is_finite())
            .collect();
        let gt: Vec<(f64, f64)> = track
            .rows
            .iter()
            .filter_map(|r| {
                tb.get(&r.frame)
                    .map(|t| (r.frame as f64, t.theta[c] * 100.0))
            })
            .filter(|p| p.1.is_finite())
            .collect();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (_, m, s) in &est {
            lo = lo.min(m - s);
            hi = hi.max(m + s);
        }
        for (_, g) in &gt {
            lo = lo.min(*g);
            hi = hi.max(*g);
        }
        if !(lo.is_finite() && hi.is_finite()) {
            lo = -1.0;
            hi = 1.0;
        }
        let pad = 0.05 * (hi - lo).max(1.0);
        let mut b = ChartBuilder::on(area);
        b.margin(10);
        if text {
            let name = if c == 0 {
                "θ_u (actor x), cm"
            } else {
                "θ_v (actor y), cm"
            };
            b.caption(name, ("sans-serif", 18))
                .x_label_area_size(30)
                .y_label_area_size(45);
        }
        let mut chart = b.build_cartesian_2d(x_range(track), (lo - pad)..(hi + pad))?;
        if text {
            chart.configure_mesh().x_desc("frame").draw()?;
        }
        let mut band: Vec<(f64, f64)> = est.iter().map(|(x, m, s)| (*x, m + s)).collect();
        band.extend(est.iter().rev().map(|(x, m, s)| (*x, m - s)));
        chart.draw_series(std::iter::once(Polygon::new(band, PALETTE[1].mix(0.25))))?;
        let s = chart.draw_series(LineSeries::new(
            est.iter().map(|(x, m, _)| (*x, *m)),
            PALETTE[1].stroke_width(2),
        ))?;
        if text {
            s.label("estimate ± std").legend(|(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], PALETTE[1].stroke_width(2))
            });
        }
        let s = chart.draw_series(gt.iter().map(|p| Circle::new(*p, 1, BLACK.filled())))?;
        if text {
            s.label("truth")
                .legend(|(x, y)| Circle::new((x + 9, y), 2, BLACK.filled()));
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }
    }
    root.present()?;
    Ok(())
}

fn fingertip(path: &Path, track: &Trajectory, truth: &Trajectory, text: bool) -> DrawResult {
    let root = BitMapBackend::new(path, (900, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let tb = truth_by_frame(truth);
    for (c, area) in root.split_evenly((3, 1)).iter().enumerate() {
        let est: Vec<(f64, f64)> = track
            .rows
            .iter()
            .map(|r| (r.frame as f64, r.pose[6 + c] * 100.0))
            .collect();
        let gt: Vec<(f64, f64)> = track
            .rows
            .iter()
            .filter_map(|r| {
                tb.get(&r.frame)
                    .map(|t| (r.frame as f64, t.pose[6 + c] * 100.0))
            })
            .collect();
        let all = est.iter().chain(&gt).map(|p| p.1).filter(|v| v.is_finite());
        let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        let (lo, hi) = if lo.is_finite() {
            (lo, hi)
        } else {
            (-1.0, 1.0)
        };
        let pad = 0.05 * (hi - lo).max(1.0);
        let mut b = ChartBuilder::on(area);
        b.margin(8);
        if text {
            b.caption(
                format!("fingertip {} (world), cm", ["x", "y", "z"][c]),
                ("sans-serif", 16),
            )
            .x_label_area_size(28)
            .y_label_area_size(45);
        }
        let mut chart = b.build_cartesian_2d(x_range(track), (lo - pad)..(hi + pad))?;
        if text {
            chart.configure_mesh().draw()?;
        }
        let s = chart.draw_series(LineSeries::new(gt, BLACK.stroke_width(2)))?;
        if text {
            s.label("truth").legend(|(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(2))
            });
        }
        let s = chart.draw_series(LineSeries::new(est, PALETTE[0].stroke_width(2)))?;
        if text {
            s.label("estimate (median-filtered best particle)")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], PALETTE[0].stroke_width(2))
                });
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }
    }
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track_csv::TrajRow;

    fn data() -> (Trajectory, Trajectory) {
        let mut truth = Trajectory::default();
        let mut track = Trajectory {
            actions: vec!["point".into(), "push".into()],
            rows: vec![],
        };
        for f in 0..40usize {
            let x = f as f64 / 40.0;
            let pose = [0.0, 0.0, 1.1, 0.0, 0.1, 0.8, 0.0, 0.3 + 0.3 * x, 0.8];
            let a = if f < 20 { "point" } else { "push" };
            truth
                .rows
                .push(TrajRow::truth(f, f as f64 / 30.0, a, [0.0, 0.4], pose));
            track.rows.push(TrajRow {
                posterior: vec![1.0 - x, x],
                theta_std: Some([0.1 * (1.0 - x), 0.05]),
                entropy: Some(0.5),
                ess: Some(10.0),
                ..TrajRow::truth(f, f as f64 / 30.0, a, [0.01, 0.41], pose)
            });
        }
        (track, truth)
    }

    /// Both variants draw: with text (when a font is found) and without any text (the fallback).
    #[test]
    fn plots_with_and_without_text() {
        type Plot = fn(&Path, &Trajectory, &Trajectory, bool) -> DrawResult;
        let (track, truth) = data();
        let d = tempfile::tempdir().unwrap();
        for f in [posterior as Plot, theta, fingertip] {
            let p = d.path().join("x.png");
            f(&p, &track, &truth, false).unwrap();
            assert!(image::open(&p).is_ok());
        }
        let paths = write_all(&track, &truth, d.path()).unwrap();
        for p in paths {
            let img = image::open(&p).unwrap();
            assert!(img.width() >= 900);
        }
    }
}
