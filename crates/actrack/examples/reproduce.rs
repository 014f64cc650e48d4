//! Reproduces the paper's experiment on real motion (issue 9) and writes `docs/results.md`.
//!
//! `cargo run --release -p actrack --example reproduce -- [--out DIR] [--docs DIR] [--quick]`
//! (run from the project root; `scripts/reproduce-paper` does this). Models are cached in
//! `--out` and reused when present.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use actrack::manifest::Manifest;
use actrack::mocap::ArmSide;
use actrack::model::ActionModel;
use actrack::pipeline::ContourMethod;
use actrack::reproduce::{
    Condition, ConditionResult, TestTrial, VideoRun, back_to_back, run_condition, run_video,
    scene_for, subject_lengths, summarise, two_action_label,
};
use actrack::train::{Progress, fit_actions, import_manifest};
use rayon::prelude::*;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

struct Args {
    out: PathBuf,
    docs: PathBuf,
    quick: bool,
}

fn args() -> Args {
    let mut a = Args {
        out: PathBuf::from("target/repro"),
        docs: PathBuf::from("docs"),
        quick: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(s) = it.next() {
        match s.as_str() {
            "--out" => a.out = it.next().map_or(a.out, PathBuf::from),
            "--docs" => a.docs = it.next().map_or(a.docs, PathBuf::from),
            "--quick" => a.quick = true,
            other => eprintln!("reproduce: ignoring argument `{other}`"),
        }
    }
    a
}

fn model(manifest: &Path, cache: &Path) -> Res<(ActionModel, f64)> {
    if cache.exists() {
        eprintln!("model: reusing {}", cache.display());
        return Ok((ActionModel::load(cache)?, 0.0));
    }
    let t0 = Instant::now();
    let m = Manifest::load(manifest)?;
    let quiet = |_: Progress| {};
    let trials = import_manifest(&m, None, &quiet)?;
    eprintln!(
        "model: training on {} trials of {}…",
        trials.len(),
        manifest.display()
    );
    let model = fit_actions(
        &trials,
        &m.options,
        &m.preprocessing,
        Some(manifest),
        &quiet,
    )?;
    model.save(cache)?;
    Ok((model, t0.elapsed().as_secs_f64()))
}

fn cm(x: f64) -> String {
    if x.is_finite() {
        format!("{:.1}", 100.0 * x)
    } else {
        "–".into()
    }
}

fn row(r: &ConditionResult) -> String {
    let e = &r.report;
    format!(
        "| {} | {} | {} | {} | {} / {} / {} | {} | {} | {:.1} % ({}/{}) | {} | {:.1} |",
        r.condition.name,
        cm(e.overall.rmse),
        cm(r.best_particle.rmse),
        cm(e.overall.mae),
        cm(e.shoulder.rmse),
        cm(e.elbow.rmse),
        cm(e.fingertip.rmse),
        cm(e.table_error),
        cm(e.theta_error),
        100.0 * e.recognition_rate,
        e.instances.iter().filter(|i| i.correct).count(),
        e.instances.len(),
        e.mean_frames_to_converge
            .map_or("never".into(), |f| format!("{f:.0}")),
        r.ms_per_frame,
    )
}

fn confusion(r: &ConditionResult) -> String {
    let mut s = format!("| {} \\ predicted |", r.condition.name);
    for a in &r.actions {
        let _ = write!(s, " {a} |");
    }
    s.push_str("\n|---|");
    for _ in &r.actions {
        s.push_str("---|");
    }
    s.push('\n');
    for (a, rowv) in r.actions.iter().zip(&r.confusion) {
        let _ = write!(s, "| **{a}** |");
        for c in rowv {
            let _ = write!(s, " {c} |");
        }
        s.push('\n');
    }
    s
}

fn small_png(img: &image::RgbImage, path: &Path) -> Res<()> {
    // Crop to the workspace (the README's u 214–488, v 45–443, widened) and halve.
    let crop = image::imageops::crop_imm(img, 160, 20, 400, 450).to_image();
    let half = image::imageops::resize(&crop, 200, 225, image::imageops::FilterType::Triangle);
    half.save(path)?;
    Ok(())
}

fn relabel(trials: &[TestTrial]) -> Vec<TestTrial> {
    trials
        .iter()
        .map(|t| TestTrial {
            action: two_action_label(&t.action),
            ..t.clone()
        })
        .collect()
}

#[allow(clippy::too_many_lines)]
fn write_docs(
    a: &Args,
    results: &[(String, ConditionResult)],
    figs: &[PathBuf],
    total: f64,
    train2: f64,
    train3: f64,
) -> Res<()> {
    let json = serde_json::to_string_pretty(
        &results
            .iter()
            .map(|(g, r)| serde_json::json!({"group": g, "result": r}))
            .collect::<Vec<_>>(),
    )?;
    std::fs::write(a.out.join("results.json"), json)?;

    let mut md = String::new();
    let head = "| condition | joint RMSE (cm) | RMSE, unfiltered best particle (cm) | MAE (cm) | RMSE p / q / r (cm) | table error (cm) | ‖θ̄ − θ‖ (cm) | recognition | frames to θ std < 2 cm | ms / frame |\n|---|---|---|---|---|---|---|---|---|---|\n";
    let paper = "| **paper** (real video, 1 actor, point/push) | 3.3 | – | 2.4 | – | 1.3 | – | ≈ 98 % (≈ 78/80) | ≈ 60 | 3900 |\n";
    let _ = writeln!(
        md,
        "# Results: the paper's experiment on real motion\n\n\
         Regenerated by `scripts/reproduce-paper` ({}; this run took {:.0} s on the machine's cores{}). \
         Numbers are measured, nothing is copied; the paper's row is from SPEC.md §5.2.\n",
        if a.quick {
            "`--quick`: repetition 1 only"
        } else {
            "full run"
        },
        total,
        if train2 + train3 > 0.0 {
            format!(", training {:.0} s of it", train2 + train3)
        } else {
            ", models reused from the cache".into()
        }
    );
    md.push_str(
        "## Setup, and how it differs from the paper\n\n\
         * **Motion is real, video is synthetic.** Training: UE-ADL subjects ADL001–ADL007, both arms \
         (left mirrored), `manifests/ue-adl-train.toml` (reach = F + A trials, drink = D) and \
         `manifests/ue-adl3-train.toml` (reach-forward / reach-across / drink); 20 states, jumps ≤ 3. \
         Test: every right-arm F, A and D trial of the held-out subjects ADL008–ADL010, their real \
         Vicon joint trajectories (actor frame, trimmed at rest, resampled to 30 fps) rendered into \
         640×480 frames with the scene synthesis (textured clutter, table, torso, head, shaded arm, \
         Gaussian noise; one background per video). The paper filmed real video of one actor with \
         point and push actions; our actions are reach / drink (and forward / across / drink).\n\
         * **World.** The actor's shoulder at (0, 0, 1.0) m, heading 0; the table 0.33 m below it. \
         Camera as the data README suggests: (0.6, 1.3, 0.6) m in the actor frame looking at \
         (−0.1, 0.3, −0.1), 65° horizontal field of view. Second view (two-camera run): \
         (−0.8, 1.2, 0.6) looking at the same point, γ = 0.15·√2 so that the summed two-view score \
         keeps the single-view sharpness (the render crate's note on Eq. 4).\n\
         * **θ prior.** Each action draws θ from the box around its *own* training targets, padded \
         by 5 cm, and θ is reflected at that box enlarged by 1.25 (`--theta-prior training`, the \
         `track` default; not in the paper, which uses one 30 × 80 cm table region for all \
         actions). θ is normalised by the box around the training targets of all actions, padded \
         by 5 cm. The ablation \"θ prior = common region\" is the paper's single region. The choice \
         was made on training subjects ADL006–007 (rendered the same way), not on the test \
         subjects.\n\
         * **Arm geometry.** The renderer and the arm-length correction use each test subject's median \
         arm lengths (measured once per actor, like a calibration); the PHMMs are the training subjects'.\n\
         * **Tracker.** SPEC defaults: 400 particles, σ₀ = 0.4 half-extents cooled to 1/16, loop \
         grammar with uniform switching, systematic resampling every frame, causal 5-frame median \
         of the best particle as the reported pose. The ablation \"particle speeds\" (not in the \
         paper) gives each particle a speed drawn log-uniformly from [0.8, 2.0] per action \
         instance (⌊s⌋ transition draws per frame plus one with probability s − ⌊s⌋; \
         `track --speed-range`), a range chosen on training subjects ADL006–007. Each trial is its own video (filter reset), except \
         the long videos.\n\
         * **Metrics** (SPEC §5.4): per-component RMSE / MAE over all frames of all trials; table \
         error = mean |r̂ − r| per component at each instance's frame of maximal extension; \
         recognition = argmax posterior at the instance's last frame; ms / frame = edge image + filter \
         step, one thread per video (two videos run at once on two cores), rendering excluded.\n\n",
    );
    md.push_str("## Headline (monocular, held-out subjects)\n\n");
    md.push_str(head);
    md.push_str(paper);
    for (g, r) in results {
        if g == "main" || g == "long" {
            md.push_str(&row(r));
            md.push('\n');
        }
    }
    md.push_str("\n## Ablations (reach + drink, repetitions 1 and 3 of every task)\n\n");
    md.push_str(head);
    for (g, r) in results {
        if g == "ablation" {
            md.push_str(&row(r));
            md.push('\n');
        }
    }
    md.push_str("\n## Confusion matrices (action instances)\n\n");
    for (g, r) in results {
        if g != "ablation" {
            md.push_str(&confusion(r));
            md.push('\n');
        }
    }
    md.push_str("## Figures (first test subject's long video)\n\n");
    for f in figs {
        let name = f.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let _ = writeln!(md, "![{name}](results/{name})\n");
    }
    md.push_str(
        "`*_posterior.png` is the Fig. 5 analogue (action posterior over time, truth as a band), \
         `*_theta.png` Fig. 1 (θ̄ ± std against the truth), `*_fingertip.png` Fig. 4 (fingertip x, y, z). \
         Overlays: the best particle's contour (yellow) and θ̄ on the table (dot), cropped and halved.\n\n",
    );
    md.push_str("## Other measurements\n\n");
    for (g, r) in results {
        let _ = writeln!(
            md,
            "* {g} / {}: {} videos, {} frames, joints in view {:.1} %, rendering {:.1} ms/frame, wall {:.0} s.",
            r.condition.name,
            r.videos,
            r.report.frames,
            100.0 * r.in_view,
            r.render_ms_per_frame,
            r.wall_seconds
        );
    }
    // Everything after the marker is written by hand: keep it across regenerations.
    md.push_str(MARKER);
    let path = a.docs.join("results.md");
    if let Ok(old) = std::fs::read_to_string(&path)
        && let Some(i) = old.find(MARKER)
    {
        md.push_str(&old[i + MARKER.len()..]);
    }
    std::fs::write(&path, md)?;
    eprintln!(
        "wrote {} in {total:.0} s",
        a.docs.join("results.md").display()
    );
    Ok(())
}

/// The line of results.md after which the text is written by hand.
const MARKER: &str = "\n<!-- analysis -->\n";

#[allow(clippy::too_many_lines)]
fn main() -> Res<()> {
    let a = args();
    let t_all = Instant::now();
    std::fs::create_dir_all(&a.out)?;
    let fig_dir = a.docs.join("results");
    std::fs::create_dir_all(&fig_dir)?;

    let (m2, train2) = model(
        Path::new("manifests/ue-adl-train.toml"),
        &a.out.join("ue-adl.actrack.json"),
    )?;
    let (m3, train3) = model(
        Path::new("manifests/ue-adl3-train.toml"),
        &a.out.join("ue-adl3.actrack.json"),
    )?;
    let test = Manifest::load(Path::new("manifests/ue-adl3-test.toml"))?;
    let mut trials3 = actrack::reproduce::test_trials(&test, ArmSide::Right)?;
    if a.quick {
        trials3.retain(|t| t.name.ends_with('1'));
    }
    let trials2 = relabel(&trials3);
    let n_frames: usize = trials3.iter().map(|t| t.poses.len()).sum();
    eprintln!(
        "test: {} right-arm trials of ADL008–010, {n_frames} frames at 30 fps",
        trials3.len()
    );
    // Ablations on a subset (repetitions 1 and 3 of every task) to stay in the time budget.
    let subset2: Vec<TestTrial> = trials2
        .iter()
        .filter(|t| t.name.ends_with('1') || t.name.ends_with('3'))
        .cloned()
        .collect();

    let mut results: Vec<(String, ConditionResult)> = Vec::new();
    let mut go = |group: &str, m: &ActionModel, tr: &[TestTrial], c: Condition| -> Res<()> {
        let (r, _) = run_condition(m, tr, &c)?;
        eprintln!(
            "{group} / {}: RMSE {} cm (best particle {}), table {} cm, recognition {:.1} %, {:.1} ms/frame, {:.0} s",
            c.name,
            cm(r.report.overall.rmse),
            cm(r.best_particle.rmse),
            cm(r.report.table_error),
            100.0 * r.report.recognition_rate,
            r.ms_per_frame,
            r.wall_seconds
        );
        results.push((group.into(), r));
        let so_far = t_all.elapsed().as_secs_f64();
        write_docs(&a, &results, &[], so_far, train2, train3)
    };

    // 1. Monocular, reach + drink (headline) and three actions.
    go(
        "main",
        &m2,
        &trials2,
        Condition::monocular("mono, reach+drink"),
    )?;
    go(
        "main",
        &m3,
        &trials3,
        Condition::monocular("mono, forward/across/drink"),
    )?;
    // 2. Two cameras (Eq. 4, γ·√2).
    go(
        "main",
        &m2,
        &trials2,
        Condition {
            views: 2,
            ..Condition::monocular("two views, reach+drink (γ = 0.15·√2)")
        },
    )?;
    // 3. Stronger clutter and noise.
    go(
        "main",
        &m2,
        &trials2,
        Condition {
            clutter: 150,
            noise: 12.0,
            ..Condition::monocular("heavy clutter (150) + noise σ 12, reach+drink")
        },
    )?;
    // 4. Ablations (subset).
    for c in [
        Condition::monocular("M = 400 (reference)"),
        Condition {
            particles: 100,
            ..Condition::monocular("M = 100")
        },
        Condition {
            particles: 1600,
            ..Condition::monocular("M = 1600")
        },
        Condition {
            contour: ContourMethod::Analytic,
            ..Condition::monocular("analytic contour")
        },
        Condition {
            sigma_end_ratio: 1.0,
            ..Condition::monocular("no cooling (σ_end/σ_0 = 1)")
        },
        Condition {
            per_action_theta: false,
            ..Condition::monocular("θ prior = common region (SPEC §3.2)")
        },
        Condition {
            speed_range: Some(actrack::reproduce::SPEED_RANGE),
            ..Condition::monocular("particle speeds in [0.8, 2.0]")
        },
    ] {
        go("ablation", &m2, &subset2, c)?;
    }

    // 5. One long video per subject, all its trials back to back (three-action model,
    //    F1 A1 D1 F2 A2 D2 …, 6 blended transition frames).
    let t_long = Instant::now();
    let lengths = subject_lengths(&trials3);
    let subjects: Vec<String> = lengths.keys().cloned().collect();
    let long_cond = Condition::monocular("long videos (3 actions, switching)");
    let long_runs: Vec<(String, VideoRun)> = subjects
        .par_iter()
        .map(|s| -> Result<(String, VideoRun), actrack::Error> {
            let mut mine: Vec<&TestTrial> = trials3.iter().filter(|t| t.subject == *s).collect();
            mine.sort_by_key(|t| {
                let rep = t.name.chars().last().unwrap_or('0');
                let task = t.name.chars().nth(6).unwrap_or('F');
                let order = match task {
                    'F' => 0,
                    'A' => 1,
                    _ => 2,
                };
                (rep, order)
            });
            let segs = back_to_back(&mine, 6);
            // Overlays: the completion-ish middle frames of the first two actions.
            let mut marks = Vec::new();
            let mut f = 0;
            for seg in &segs {
                if !seg.action.is_empty() && marks.len() < 2 {
                    marks.push(f + seg.poses.len() / 2);
                }
                f += seg.poses.len();
            }
            let scene = scene_for(&m3, 1, lengths[s])?;
            Ok((
                s.clone(),
                run_video(&m3, &scene, &segs, &long_cond, &marks)?,
            ))
        })
        .collect::<Result<_, _>>()?;
    let runs: Vec<VideoRun> = long_runs.iter().map(|(_, r)| r.clone()).collect();
    let long = summarise(&long_cond, &m3, &runs, t_long.elapsed().as_secs_f64())?;
    eprintln!(
        "long: RMSE {} cm, recognition {:.1} %",
        cm(long.report.overall.rmse),
        100.0 * long.report.recognition_rate
    );
    results.push(("long".into(), long));

    // Figures: the first subject's long video.
    let mut figs = Vec::new();
    if let Some((s, r)) = long_runs.first() {
        let tmp = a.out.join("plots");
        let paths = actrack::plots::write_all(&r.track, &r.truth, &tmp)?;
        for p in paths {
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("plot.png");
            let dst = fig_dir.join(format!("{}_{name}", s.to_lowercase()));
            std::fs::copy(&p, &dst)?;
            figs.push(dst);
        }
        for (f, img) in &r.overlays {
            let dst = fig_dir.join(format!("{}_overlay_{f:05}.png", s.to_lowercase()));
            small_png(img, &dst)?;
            figs.push(dst);
        }
    }

    let total = t_all.elapsed().as_secs_f64();
    write_docs(&a, &results, &figs, total, train2, train3)?;
    Ok(())
}
