//! The generalisation benchmark: held-out trials rendered in randomised scene styles
//! ([`actrack::style::Style::random`]) and tracked with one configuration (the defaults).
//!
//! Every style is a different camera, look and degradation of the same trials; the benchmark
//! reports each style's metrics, the median over styles and the worst quartile of styles, and θ's
//! error part-way through each movement (the prediction before the hand arrives).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::time::Instant;

use actrack::Result;
use actrack::config::TrackConfig;
use actrack::eval::evaluate;
use actrack::model::ActionModel;
use actrack::style::Style;
use actrack::track_csv::Trajectory;
use actrack_render::synth::TablePattern;
use image::RgbImage;
use rayon::prelude::*;
use serde::Serialize;

use crate::reproduce::{
    ActorHeight, Condition, ConditionResult, ModelKind, Segment, TestTrial, TrialSet, VideoRun,
    merge, rest_heights, run_styled_video, subject_lengths, subject_setup, summarise,
};

/// The fractions of each movement (start → maximal extension) at which θ's error is read.
pub const FRACTIONS: [f64; 2] = [0.5, 0.75];

/// The result of one style.
#[derive(Clone, Debug, Serialize)]
pub struct StyleResult {
    /// The style.
    pub style: Style,
    /// The metrics over every trial tracked in it.
    pub result: ConditionResult,
    /// Per fraction of [`FRACTIONS`]: ‖θ̄ − θ‖ (metres) of every action instance at that
    /// fraction of the way from its first frame to its frame of maximal extension.
    pub theta_at: Vec<Vec<f64>>,
}

/// The experiment's condition of a style: the reach + drink model, one view, the style's
/// clutter and noise; the filter's seed is the style's plus `filter.seed` (the style draws its
/// own images), so `filter.seed` gives the tracker's seed-to-seed spread on the same videos.
fn condition(style: &Style, config: &TrackConfig) -> Condition {
    Condition {
        name: format!("style {}", style.seed),
        group: "generalisation".into(),
        model: ModelKind::Two,
        trials: TrialSet::All,
        views: 1,
        clutter: style.clutter,
        noise: style.noise_sigma,
        seed: style.seed.wrapping_add(config.filter.seed),
        actor_height: ActorHeight::Models,
        track: config.clone(),
    }
}

/// Tracks every trial of `trials` (each its own video, in parallel) rendered in `style` with
/// `config`, and evaluates them. The scene of each subject is [`subject_setup`]'s with the
/// style's camera in place of the experiment's.
///
/// # Errors
/// Rendering, tracking or evaluation errors, naming the frame.
pub fn run_style(
    model: &ActionModel,
    trials: &[TestTrial],
    style: &Style,
    config: &TrackConfig,
) -> Result<StyleResult> {
    let t0 = Instant::now();
    let cond = condition(style, config);
    let lengths = subject_lengths(trials);
    let rest = rest_heights(trials);
    let runs: Vec<VideoRun> = trials
        .par_iter()
        .map(|t| {
            let (scene, config) =
                subject_setup(model, &cond, &t.subject, &lengths, &rest, t.lengths)?;
            let scene = style.scene(&scene)?;
            run_styled_video(model, &scene, &[Segment::from(t)], style, &config, &[])
        })
        .collect::<Result<_>>()?;
    let result = summarise(&cond, model, &runs, t0.elapsed().as_secs_f64())?;
    let (track, truth) = merge(&runs);
    let theta_at = FRACTIONS
        .iter()
        .map(|&f| theta_errors_at(&track, &truth, f))
        .collect::<Result<_>>()?;
    Ok(StyleResult {
        style: style.clone(),
        result,
        theta_at,
    })
}

/// Tracks `trial` in `style` as [`run_style`] does and returns the overlays (the best pose's
/// contour and θ̄) of every `every`-th frame: what the tracker locks onto in that style.
///
/// # Errors
/// As [`run_style`].
pub fn style_overlays(
    model: &ActionModel,
    trials: &[TestTrial],
    trial: &TestTrial,
    style: &Style,
    config: &TrackConfig,
    every: usize,
) -> Result<Vec<(usize, RgbImage)>> {
    let cond = condition(style, config);
    let (scene, config) = subject_setup(
        model,
        &cond,
        &trial.subject,
        &subject_lengths(trials),
        &rest_heights(trials),
        trial.lengths,
    )?;
    let scene = style.scene(&scene)?;
    let frames: Vec<usize> = (0..trial.poses.len()).step_by(every.max(1)).collect();
    Ok(run_styled_video(
        model,
        &scene,
        &[Segment::from(trial)],
        style,
        &config,
        &frames,
    )?
    .overlays)
}

/// ‖θ̄ − θ‖ of every action instance of `truth` at `fraction` of the way from its first frame to
/// its frame of maximal extension (the track's θ̄ of that frame; instances without a track row
/// there are skipped).
///
/// # Errors
/// As [`evaluate`].
pub fn theta_errors_at(track: &Trajectory, truth: &Trajectory, fraction: f64) -> Result<Vec<f64>> {
    let report = evaluate(track, truth)?;
    let by_frame: BTreeMap<usize, [f64; 2]> =
        track.rows.iter().map(|r| (r.frame, r.theta)).collect();
    let truth_theta: BTreeMap<usize, [f64; 2]> =
        truth.rows.iter().map(|r| (r.frame, r.theta)).collect();
    Ok(report
        .instances
        .iter()
        .filter_map(|i| {
            let span = i.completion.saturating_sub(i.start) as f64;
            let f = i.start + (fraction * span).round() as usize;
            let (est, gt) = (by_frame.get(&f)?, truth_theta.get(&f)?);
            let e = (est[0] - gt[0]).hypot(est[1] - gt[1]);
            e.is_finite().then_some(e)
        })
        .collect())
}

/// The `q`-quantile of `v` (linear interpolation between order statistics); NaN when empty.
pub fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let x = q.clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let (lo, hi) = (x.floor() as usize, x.ceil() as usize);
    s[lo] + (x - lo as f64) * (s[hi] - s[lo])
}

/// One line saying what a style looks like: camera, image, light and degradations.
pub fn describe(s: &Style) -> String {
    let c = &s.camera;
    let a = &s.appearance;
    let mut out = format!(
        "{}×{}, az {:+.0}°, el {:.0}°, {:.1} m, {:.0}° fov",
        c.width, c.height, c.azimuth_deg, c.elevation_deg, c.distance, c.hfov_deg
    );
    if c.distortion[0] != 0.0 {
        let _ = write!(out, ", k1 {:+.2}", c.distortion[0]);
    }
    let pattern = match a.table_pattern {
        TablePattern::Grain => "grain",
        TablePattern::Plain => "plain",
        TablePattern::Checker => "checker",
    };
    let _ = write!(out, ", {pattern} table");
    if a.background.is_some() {
        out.push_str(", wall ≈ sleeve");
    }
    if a.other_arm {
        out.push_str(", other arm");
    }
    if !s.cups.is_empty() {
        let _ = write!(out, ", {} cups", s.cups.len());
    }
    let _ = write!(out, ", noise {:.0}", s.noise_sigma);
    if let Some(q) = s.jpeg_quality {
        let _ = write!(out, ", JPEG {q}");
    }
    if s.blur > 1 {
        let _ = write!(out, ", blur {}", s.blur);
    }
    if s.drop_rate > 0.0 {
        let _ = write!(out, ", drops {:.0} %", 100.0 * s.drop_rate);
    }
    out
}

/// The benchmark's figures over styles.
#[derive(Clone, Debug, Serialize)]
pub struct Overall {
    /// Styles.
    pub styles: usize,
    /// Action instances over all styles.
    pub instances: usize,
    /// Median over styles of the joint RMSE (metres): all joints, shoulder, elbow, fingertip.
    pub rmse: [f64; 4],
    /// The 75th percentile over styles of the joint RMSE (the worst quartile's edge).
    pub rmse_worst_quartile: f64,
    /// Median over styles of the table-location error (metres).
    pub table_error: f64,
    /// Its 75th percentile.
    pub table_error_worst_quartile: f64,
    /// Median over styles of the recognition rate.
    pub recognition: f64,
    /// Its 25th percentile.
    pub recognition_worst_quartile: f64,
    /// Median over styles of each style's median θ error at [`FRACTIONS`] (metres).
    pub theta_at: Vec<f64>,
    /// Their 75th percentiles.
    pub theta_at_worst_quartile: Vec<f64>,
    /// Action names and `confusion[true][predicted]` summed over styles.
    pub actions: Vec<String>,
    /// The summed confusion matrix.
    pub confusion: Vec<Vec<usize>>,
    /// Mean ms per frame of the session's step.
    pub ms_per_frame: f64,
}

/// Median and worst quartile over `styles`.
pub fn overall(styles: &[StyleResult]) -> Overall {
    let per = |f: &dyn Fn(&StyleResult) -> f64| -> Vec<f64> { styles.iter().map(f).collect() };
    let rmse_all = per(&|s| s.result.report.overall.rmse);
    let table = per(&|s| s.result.report.table_error);
    let recog = per(&|s| s.result.report.recognition_rate);
    let theta: Vec<Vec<f64>> = (0..FRACTIONS.len())
        .map(|k| per(&|s| quantile(&s.theta_at[k], 0.5)))
        .collect();
    let actions = styles
        .first()
        .map(|s| s.result.actions.clone())
        .unwrap_or_default();
    let mut confusion = vec![vec![0usize; actions.len()]; actions.len()];
    for s in styles {
        for (row, r) in confusion.iter_mut().zip(&s.result.confusion) {
            for (c, x) in row.iter_mut().zip(r) {
                *c += x;
            }
        }
    }
    Overall {
        styles: styles.len(),
        instances: styles.iter().map(|s| s.result.report.instances.len()).sum(),
        rmse: [
            quantile(&rmse_all, 0.5),
            quantile(&per(&|s| s.result.report.shoulder.rmse), 0.5),
            quantile(&per(&|s| s.result.report.elbow.rmse), 0.5),
            quantile(&per(&|s| s.result.report.fingertip.rmse), 0.5),
        ],
        rmse_worst_quartile: quantile(&rmse_all, 0.75),
        table_error: quantile(&table, 0.5),
        table_error_worst_quartile: quantile(&table, 0.75),
        recognition: quantile(&recog, 0.5),
        recognition_worst_quartile: quantile(&recog, 0.25),
        theta_at_worst_quartile: theta.iter().map(|v| quantile(v, 0.75)).collect(),
        theta_at: theta.iter().map(|v| quantile(v, 0.5)).collect(),
        actions,
        confusion,
        ms_per_frame: per(&|s| s.result.ms_per_frame).iter().sum::<f64>()
            / styles.len().max(1) as f64,
    }
}

fn cm(x: f64) -> String {
    if x.is_finite() {
        format!("{:.1}", 100.0 * x)
    } else {
        "–".into()
    }
}

/// The table header of [`style_row`] and [`overall_rows`].
pub const HEAD: &str = "| style | joint RMSE (cm) | RMSE shoulder / elbow / fingertip (cm) | table error (cm) | recognition | θ error at 50 % / 75 % (cm) | ms / frame |\n|---|---|---|---|---|---|---|\n";

/// A style's row of the table.
pub fn style_row(s: &StyleResult) -> String {
    let e = &s.result.report;
    let correct = e.instances.iter().filter(|i| i.correct).count();
    format!(
        "| {}: {} | {} | {} / {} / {} | {} | {:.0} % ({correct}/{}) | {} / {} | {:.1} |",
        s.style.seed,
        describe(&s.style),
        cm(e.overall.rmse),
        cm(e.shoulder.rmse),
        cm(e.elbow.rmse),
        cm(e.fingertip.rmse),
        cm(e.table_error),
        100.0 * e.recognition_rate,
        e.instances.len(),
        cm(quantile(&s.theta_at[0], 0.5)),
        cm(quantile(&s.theta_at[1], 0.5)),
        s.result.ms_per_frame,
    )
}

/// The median and worst-quartile rows.
pub fn overall_rows(o: &Overall) -> String {
    format!(
        "| **median over {} styles** | **{}** | {} / {} / {} | **{}** | **{:.1} %** | **{} / {}** | {:.1} |\n\
         | worst quartile (75th / 25th percentile) | {} | | {} | {:.1} % | {} / {} | |\n",
        o.styles,
        cm(o.rmse[0]),
        cm(o.rmse[1]),
        cm(o.rmse[2]),
        cm(o.rmse[3]),
        cm(o.table_error),
        100.0 * o.recognition,
        cm(o.theta_at[0]),
        cm(o.theta_at[1]),
        o.ms_per_frame,
        cm(o.rmse_worst_quartile),
        cm(o.table_error_worst_quartile),
        100.0 * o.recognition_worst_quartile,
        cm(o.theta_at_worst_quartile[0]),
        cm(o.theta_at_worst_quartile[1]),
    )
}

/// The confusion matrix summed over styles.
pub fn confusion_table(o: &Overall) -> String {
    let mut s = String::from("| true \\ predicted |");
    for a in &o.actions {
        let _ = write!(s, " {a} |");
    }
    s.push_str("\n|---|");
    for _ in &o.actions {
        s.push_str("---|");
    }
    s.push('\n');
    for (a, row) in o.actions.iter().zip(&o.confusion) {
        let _ = write!(s, "| **{a}** |");
        for c in row {
            let _ = write!(s, " {c} |");
        }
        s.push('\n');
    }
    s
}

/// Marks the start of the benchmark's block in docs/results.md.
pub const BEGIN: &str = "<!-- generalisation: begin (scripts/generalisation writes this block) -->";
/// Marks its end.
pub const END: &str = "<!-- generalisation: end -->";

/// The block between [`BEGIN`] and [`END`] of `page`, markers included.
pub fn block_of(page: &str) -> Option<&str> {
    let a = page.find(BEGIN)?;
    let b = page[a..].find(END)? + a + END.len();
    Some(&page[a..b])
}

/// `page` with its block replaced by `block` (markers included), or `block` inserted before the
/// heading `before` (appended when the page has no such heading).
pub fn with_block(page: &str, block: &str, before: &str) -> String {
    if let Some(old) = block_of(page) {
        return page.replacen(old, block, 1);
    }
    match page.find(before) {
        Some(i) => format!("{}{block}\n\n{}", &page[..i], &page[i..]),
        None => format!("{}\n{block}\n", page.trim_end()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use actrack::track_csv::TrajRow;

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let v = [4.0, 1.0, 3.0, 2.0, f64::NAN];
        assert!((quantile(&v, 0.5) - 2.5).abs() < 1e-12);
        assert!((quantile(&v, 0.75) - 3.25).abs() < 1e-12);
        assert!((quantile(&v, 0.0) - 1.0).abs() < 1e-12);
        assert!(quantile(&[], 0.5).is_nan());
    }

    #[test]
    fn theta_error_is_read_part_way_to_the_maximal_extension() {
        // One reach: the fingertip moves out along x for frames 0..=10 and back; θ = (1, 0).
        let mut truth = Trajectory::default();
        let mut track = Trajectory {
            actions: vec!["reach".into()],
            rows: Vec::new(),
        };
        for f in 0..16usize {
            let x = if f <= 10 { f as f64 } else { 20.0 - f as f64 } * 0.05;
            let pose = [0.0, 0.0, 1.0, 0.1, 0.0, 0.9, x, 0.0, 0.7];
            truth.rows.push(TrajRow::truth(
                f,
                f as f64 / 30.0,
                "reach",
                [1.0, 0.0],
                pose,
            ));
            let mut row = TrajRow::truth(f, f as f64 / 30.0, "", [1.0, f as f64], pose);
            row.posterior = vec![1.0];
            row.theta_std = Some([0.01, 0.01]);
            track.rows.push(row);
        }
        // Completion at frame 10: 50 % is frame 5 (θ̄ off by 5 m), 75 % frame 8 (off by 8).
        assert_eq!(theta_errors_at(&track, &truth, 0.5).unwrap(), vec![5.0]);
        assert_eq!(theta_errors_at(&track, &truth, 0.75).unwrap(), vec![8.0]);
    }

    #[test]
    fn the_block_is_replaced_in_place_or_inserted_before_the_heading() {
        let block = format!("{BEGIN}\nnew\n{END}");
        let page = "# R\n\n## Seed spread\n\nx\n";
        let once = with_block(page, &block, "## Seed spread");
        assert_eq!(once, format!("# R\n\n{block}\n\n## Seed spread\n\nx\n"));
        let other = format!("{BEGIN}\nnewer\n{END}");
        let twice = with_block(&once, &other, "## Seed spread");
        assert_eq!(twice, format!("# R\n\n{other}\n\n## Seed spread\n\nx\n"));
        assert_eq!(block_of(&twice), Some(other.as_str()));
    }
}
