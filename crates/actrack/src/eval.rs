//! Evaluation metrics of SPEC §5.4: per-component RMSE and MAE of the shoulder, elbow and
//! fingertip; the table-location error at each action's completion frame (the frame of maximal
//! ground-truth arm extension ‖r − p‖); ‖θ̄ − θ_gt‖; recognition per ground-truth action instance
//! at its last frame; and the frames until θ's std falls under 2 cm.
//!
//! Track and truth rows are matched by frame index. Frames whose ground-truth action is empty are
//! not evaluated. An action instance is a maximal run of consecutive frames with the same action
//! name and θ.

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::track_csv::{TrajRow, Trajectory};

/// θ std under which an estimate counts as converged (metres).
pub const CONVERGED_STD: f64 = 0.02;

/// RMSE and MAE of one joint or of all (metres).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct ErrorStats {
    /// sqrt(mean e²) over frames and x, y, z.
    pub rmse: f64,
    /// mean |e| over frames and x, y, z.
    pub mae: f64,
}

/// One ground-truth action instance.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct InstanceReport {
    /// Ground-truth action.
    pub action: String,
    /// First frame.
    pub start: usize,
    /// Last frame.
    pub end: usize,
    /// Completion frame (maximal ground-truth extension).
    pub completion: usize,
    /// argmax of the posterior at the last frame.
    pub predicted: String,
    /// Whether `predicted == action`.
    pub correct: bool,
    /// Mean |r̂_c − r_c| over x, y, z at completion (metres).
    pub table_error: f64,
    /// Fingertip error (r̂ − r) at completion (metres).
    pub fingertip_error: [f64; 3],
    /// ‖θ̄ − θ_gt‖ at completion (metres); NaN when the truth has no θ.
    pub theta_error: f64,
    /// Frames from the start until max θ std < 2 cm (None: never).
    pub frames_to_converge: Option<usize>,
}

/// The evaluation result.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EvalReport {
    /// Number of evaluated frames.
    pub frames: usize,
    /// Shoulder errors.
    pub shoulder: ErrorStats,
    /// Elbow errors.
    pub elbow: ErrorStats,
    /// Fingertip errors.
    pub fingertip: ErrorStats,
    /// All joints.
    pub overall: ErrorStats,
    /// Mean table-location error over instances (metres), SPEC §5.3.
    pub table_error: f64,
    /// Mean ‖θ̄ − θ_gt‖ over instances (metres).
    pub theta_error: f64,
    /// Correctly recognised instances / instances.
    pub recognition_rate: f64,
    /// Mean frames until θ std < 2 cm over the instances that converge.
    pub mean_frames_to_converge: Option<f64>,
    /// Per-instance details.
    pub instances: Vec<InstanceReport>,
}

/// TableErr of SPEC §5.4: mean absolute component of the fingertip errors at completion.
pub fn table_error(errors: &[[f64; 3]]) -> f64 {
    if errors.is_empty() {
        return f64::NAN;
    }
    errors.iter().flatten().map(|e| e.abs()).sum::<f64>() / (3 * errors.len()) as f64
}

fn stats(sq: f64, abs: f64, n: usize) -> ErrorStats {
    if n == 0 {
        return ErrorStats {
            rmse: f64::NAN,
            mae: f64::NAN,
        };
    }
    ErrorStats {
        rmse: (sq / n as f64).sqrt(),
        mae: abs / n as f64,
    }
}

fn extension(p: &[f64; 9]) -> f64 {
    ((p[6] - p[0]).powi(2) + (p[7] - p[1]).powi(2) + (p[8] - p[2]).powi(2)).sqrt()
}

/// Splits ground truth into action instances (index ranges into `truth.rows`).
pub fn instances(truth: &Trajectory) -> Vec<std::ops::Range<usize>> {
    let rows = &truth.rows;
    let mut out = Vec::new();
    let mut i = 0;
    while i < rows.len() {
        if rows[i].action.is_empty() {
            i += 1;
            continue;
        }
        let same = |a: &TrajRow, b: &TrajRow| {
            a.action == b.action
                && b.frame == a.frame + 1
                && (0..2).all(|c| {
                    (a.theta[c] - b.theta[c]).abs() < 1e-9
                        || (a.theta[c].is_nan() && b.theta[c].is_nan())
                })
        };
        let mut j = i + 1;
        while j < rows.len() && same(&rows[j - 1], &rows[j]) {
            j += 1;
        }
        out.push(i..j);
        i = j;
    }
    out
}

/// Evaluates a track against ground truth.
pub fn evaluate(track: &Trajectory, truth: &Trajectory) -> Result<EvalReport> {
    let by_frame: BTreeMap<usize, &TrajRow> = track.rows.iter().map(|r| (r.frame, r)).collect();
    let mut sq = [0.0; 3];
    let mut ab = [0.0; 3];
    let mut n = 0usize;
    for t in truth.rows.iter().filter(|r| !r.action.is_empty()) {
        let Some(e) = by_frame.get(&t.frame) else {
            continue;
        };
        n += 1;
        for j in 0..3 {
            for c in 0..3 {
                let d = e.pose[3 * j + c] - t.pose[3 * j + c];
                sq[j] += d * d;
                ab[j] += d.abs();
            }
        }
    }
    if n == 0 {
        return Err(Error::Config(
            "the track and the ground truth share no frame with a ground-truth action: nothing to evaluate".into(),
        ));
    }
    let mut inst = Vec::new();
    for range in instances(truth) {
        let rows = &truth.rows[range];
        let Some(last) = rows
            .iter()
            .rev()
            .find_map(|r| by_frame.get(&r.frame).map(|e| (r, *e)))
        else {
            continue;
        };
        let Some(done) = rows
            .iter()
            .filter(|r| by_frame.contains_key(&r.frame))
            .max_by(|a, b| extension(&a.pose).total_cmp(&extension(&b.pose)))
        else {
            continue;
        };
        let est = by_frame[&done.frame];
        let fe = [0, 1, 2].map(|c| est.pose[6 + c] - done.pose[6 + c]);
        let theta_error = (est.theta[0] - done.theta[0]).hypot(est.theta[1] - done.theta[1]);
        let predicted = last
            .1
            .posterior
            .iter()
            .enumerate()
            .filter(|(_, p)| !p.is_nan())
            .max_by(|a, b| a.1.total_cmp(b.1))
            .and_then(|(i, _)| track.actions.get(i).cloned())
            .unwrap_or_else(|| last.1.action.clone());
        let start = rows[0].frame;
        let frames_to_converge = rows
            .iter()
            .filter_map(|r| by_frame.get(&r.frame))
            .find_map(|e| {
                e.theta_std
                    .filter(|s| s[0].max(s[1]) < CONVERGED_STD)
                    .map(|_| e.frame - start)
            });
        inst.push(InstanceReport {
            action: rows[0].action.clone(),
            start,
            end: rows[rows.len() - 1].frame,
            completion: done.frame,
            correct: predicted == rows[0].action,
            predicted,
            table_error: table_error(&[fe]),
            fingertip_error: fe,
            theta_error,
            frames_to_converge,
        });
    }
    let k = inst.len().max(1) as f64;
    let conv: Vec<f64> = inst
        .iter()
        .filter_map(|i| i.frames_to_converge.map(|f| f as f64))
        .collect();
    let thetas: Vec<f64> = inst
        .iter()
        .map(|i| i.theta_error)
        .filter(|x| !x.is_nan())
        .collect();
    Ok(EvalReport {
        frames: n,
        shoulder: stats(sq[0], ab[0], 3 * n),
        elbow: stats(sq[1], ab[1], 3 * n),
        fingertip: stats(sq[2], ab[2], 3 * n),
        overall: stats(sq.iter().sum(), ab.iter().sum(), 9 * n),
        table_error: table_error(&inst.iter().map(|i| i.fingertip_error).collect::<Vec<_>>()),
        theta_error: if thetas.is_empty() {
            f64::NAN
        } else {
            thetas.iter().sum::<f64>() / thetas.len() as f64
        },
        recognition_rate: inst.iter().filter(|i| i.correct).count() as f64 / k,
        mean_frames_to_converge: (!conv.is_empty())
            .then(|| conv.iter().sum::<f64>() / conv.len() as f64),
        instances: inst,
    })
}

impl fmt::Display for EvalReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let cm = |x: f64| x * 100.0;
        writeln!(f, "frames evaluated: {}", self.frames)?;
        writeln!(f, "{:<10} {:>9} {:>9}", "joint", "RMSE cm", "MAE cm")?;
        for (name, s) in [
            ("shoulder", self.shoulder),
            ("elbow", self.elbow),
            ("fingertip", self.fingertip),
            ("overall", self.overall),
        ] {
            writeln!(f, "{name:<10} {:>9.2} {:>9.2}", cm(s.rmse), cm(s.mae))?;
        }
        writeln!(
            f,
            "table-location error: {:.2} cm   |θ̄ − θ_gt|: {:.2} cm",
            cm(self.table_error),
            cm(self.theta_error)
        )?;
        let ok = self.instances.iter().filter(|i| i.correct).count();
        writeln!(
            f,
            "recognition: {ok}/{} = {:.0} %",
            self.instances.len(),
            100.0 * self.recognition_rate
        )?;
        match self.mean_frames_to_converge {
            Some(m) => writeln!(f, "frames until θ std < 2 cm: {m:.1} (mean)")?,
            None => writeln!(f, "frames until θ std < 2 cm: never")?,
        }
        writeln!(
            f,
            "{:<8} {:>6} {:>6} {:>6} {:<8} {:>9} {:>9} {:>6}",
            "action", "start", "end", "done", "predicted", "table cm", "θ cm", "conv"
        )?;
        for i in &self.instances {
            writeln!(
                f,
                "{:<8} {:>6} {:>6} {:>6} {:<8}{} {:>9.2} {:>9.2} {:>6}",
                i.action,
                i.start,
                i.end,
                i.completion,
                i.predicted,
                if i.correct { " " } else { "✗" },
                cm(i.table_error),
                cm(i.theta_error),
                i.frames_to_converge.map_or("-".into(), |c| c.to_string())
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SPEC §7 test 13: the TableErr of Table 1's errors is 1.307 cm.
    #[test]
    fn table1_aggregate() {
        let cm = [
            [-2.53, -0.53, 0.72],
            [-3.77, -0.48, -0.36],
            [-0.05, -1.70, 1.62],
        ];
        assert!((table_error(&cm) - 1.307).abs() < 1e-3);
        // The same through `evaluate`: three pointing instances whose completion frames
        // (61, 195, 301) carry the Table 1 fingertip errors.
        let mut truth = Trajectory::default();
        let mut track = Trajectory {
            actions: vec!["point".into(), "push".into()],
            rows: vec![],
        };
        let completions = [61usize, 195, 301];
        for f in 0..360usize {
            let inst = completions.iter().position(|c| f <= c + 40 && f + 40 >= *c);
            let action = inst.map_or("", |_| "point");
            let ext = inst.map_or(0.3, |i| {
                0.7 - (f as f64 - completions[i] as f64).abs() * 0.005
            });
            let pose = [0.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0, ext, 0.0];
            let theta = inst.map_or([f64::NAN; 2], |i| [i as f64 * 0.1, 0.5]);
            truth
                .rows
                .push(TrajRow::truth(f, f as f64 / 30.0, action, theta, pose));
            let mut est = pose;
            if let Some(i) = inst
                && f == completions[i]
            {
                for c in 0..3 {
                    est[6 + c] += cm[i][c] / 100.0;
                }
            }
            track.rows.push(TrajRow {
                posterior: vec![0.9, 0.1],
                theta_std: Some([0.01, 0.01]),
                entropy: Some(0.1),
                ess: Some(10.0),
                ..TrajRow::truth(f, f as f64 / 30.0, "point", theta, est)
            });
        }
        let r = evaluate(&track, &truth).unwrap();
        assert_eq!(r.instances.len(), 3);
        assert_eq!(
            r.instances.iter().map(|i| i.completion).collect::<Vec<_>>(),
            completions
        );
        assert!(
            (r.table_error * 100.0 - 1.307).abs() < 1e-3,
            "{}",
            r.table_error
        );
        assert!((r.recognition_rate - 1.0).abs() < 1e-12);
        assert_eq!(r.instances[0].frames_to_converge, Some(0));
        assert!(r.to_string().contains("table-location error: 1.31 cm"));
    }

    #[test]
    fn rmse_and_mae_per_component() {
        // Constant error (3, 4, 0) cm on the fingertip only.
        let mut truth = Trajectory::default();
        let mut track = Trajectory {
            actions: vec!["a".into()],
            rows: vec![],
        };
        for f in 0..10 {
            let pose = [0.0, 0.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.7, 0.0];
            truth
                .rows
                .push(TrajRow::truth(f, 0.0, "a", [0.0, 0.7], pose));
            let mut est = pose;
            est[6] += 0.03;
            est[7] += 0.04;
            track.rows.push(TrajRow {
                posterior: vec![1.0],
                theta_std: Some([0.1, 0.1]),
                ..TrajRow::truth(f, 0.0, "a", [0.0, 0.7], est)
            });
        }
        let r = evaluate(&track, &truth).unwrap();
        assert!((r.fingertip.rmse - (0.0025f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((r.fingertip.mae - 0.07 / 3.0).abs() < 1e-12);
        assert!((r.overall.rmse - (0.0025f64 / 9.0).sqrt()).abs() < 1e-12);
        assert!(r.shoulder.rmse.abs() < 1e-12);
        assert_eq!(r.instances[0].frames_to_converge, None);
    }
}
