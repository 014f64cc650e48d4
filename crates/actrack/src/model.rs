//! [`ActionModel`]: the learned action models (one parametric HMM per action), the arm geometry,
//! the θ frame and the training provenance — and its file, `*.actrack.json`.
//!
//! The file is JSON: `{"format": "actrack-model", "version": 1, "actions": [...], ...}`. Each
//! action carries its parametric HMM (π, banded A, exit probabilities, per-state W̄/μ̄ and
//! covariance, as serialised by `actrack-phmm`), the mean, covariance and range of its training
//! θ, and its final training log-likelihood. Reading checks `format` and `version` first (an
//! unknown version is a clear error, never a guess), then the whole structure; the PHMMs are
//! validated on load. Writing goes to a temporary name, then a rename.

use std::path::Path;

use actrack_phmm::Phmm;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::mocap::trial::Preprocessing;

/// The `format` value of a model file.
pub const FORMAT: &str = "actrack-model";
/// The model file version this build reads and writes.
pub const VERSION: u32 = 1;

/// The file name of the default model shipped in `models/` (reach and drink, every UE-ADL subject).
pub const DEFAULT_MODEL_NAME: &str = "reach-drink.v1.actrack.json";

/// The default model's file, built into the library.
const DEFAULT_MODEL_JSON: &str = include_str!("../../../models/reach-drink.v1.actrack.json");

/// The default model shipped in `models/` ([`DEFAULT_MODEL_NAME`]), built into the library so
/// that it needs no file at run time.
pub fn default_model() -> Result<ActionModel> {
    ActionModel::from_json(Path::new(DEFAULT_MODEL_NAME), DEFAULT_MODEL_JSON)
}

/// One action: its parametric HMM and what it was trained on.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Action {
    /// Action label (e.g. `reach`, `drink`).
    pub name: String,
    /// The parametric HMM over 9-D actor-frame poses (p, q, r), θ = 2-D table target.
    pub phmm: Phmm,
    /// Mean of the training θ (actor frame, metres).
    pub theta_mean: [f64; 2],
    /// Covariance of the training θ (m²).
    pub theta_cov: [[f64; 2]; 2],
    /// Smallest training θ per axis.
    pub theta_min: [f64; 2],
    /// Largest training θ per axis.
    pub theta_max: [f64; 2],
    /// Number of training trials.
    pub n_trials: usize,
    /// Baum–Welch iterations run.
    pub iterations: usize,
    /// Whether Baum–Welch converged within the iteration limit.
    pub converged: bool,
    /// Final total training log-likelihood.
    pub final_log_likelihood: f64,
    /// Median training-trial length in frames (at the model's frame rate).
    pub median_frames: f64,
}

/// Arm segment lengths (medians over the training trials), metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArmLengths {
    /// L1: shoulder → elbow.
    pub upper_arm: f64,
    /// L2: elbow → fingertip (forearm with hand, SPEC E20).
    pub forearm_hand: f64,
}

/// Where training data came from and how the model was made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Tool and version, e.g. `actrack 0.1.0`.
    pub tool: String,
    /// Creation time, ISO 8601 UTC.
    pub created: String,
    /// The manifest, if any.
    pub manifest: Option<String>,
    /// Training files (movement trials) in order.
    pub files: Vec<String>,
    /// States per action.
    pub states: usize,
    /// Maximum forward jump.
    pub max_jump: usize,
    /// Iteration limit.
    pub max_iterations: usize,
    /// Covariance floor σ_min, metres.
    pub cov_floor: f64,
}

/// A set of named action models with the geometry and frames they live in.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ActionModel {
    /// The actions, in training order.
    pub actions: Vec<Action>,
    /// Arm segment lengths.
    pub arm_lengths: ArmLengths,
    /// Words describing the frame of poses and θ.
    pub theta_frame: String,
    /// How trials were prepared (frame rate, trimming, θ rule, marker set); `classify` applies
    /// the same.
    pub preprocessing: Preprocessing,
    /// Training provenance.
    pub provenance: Provenance,
}

/// Description of the frame poses and θ are expressed in.
pub const THETA_FRAME: &str = "actor frame (DESIGN.md): origin = acting shoulder landmark of the \
    static trial, x = actor's right, y = across the table away from the actor, z = up; metres; \
    left arms mirrored onto the right (x -> -x); theta = fingertip (x, y) on the table";

#[derive(Serialize)]
struct FileOut<'a> {
    format: &'a str,
    version: u32,
    #[serde(flatten)]
    model: &'a ActionModel,
}

#[derive(Deserialize)]
struct FileHeader {
    format: Option<String>,
    version: Option<serde_json::Value>,
}

#[derive(Deserialize)]
struct FileIn {
    #[allow(dead_code)]
    format: String,
    #[allow(dead_code)]
    version: u32,
    #[serde(flatten)]
    model: ActionModel,
}

/// A cap on the models' self-transition probabilities at tracking time (not in the paper;
/// `track --max-stay P [--keep-last-dwell]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DwellCap {
    /// The largest self-transition probability, in (0, 1]
    /// ([`Phmm::with_max_self_transition`]).
    pub max_stay: f64,
    /// Leave each model's last state uncapped
    /// ([`Phmm::with_max_self_transition_before_last`]), so that a finished action's particles
    /// stay in it while the arm rests after the action.
    pub keep_last: bool,
}

impl DwellCap {
    /// Every state capped at `max_stay`.
    pub fn all(max_stay: f64) -> Self {
        Self {
            max_stay,
            keep_last: false,
        }
    }
}

impl ActionModel {
    /// The action names in order.
    pub fn action_names(&self) -> Vec<&str> {
        self.actions.iter().map(|a| a.name.as_str()).collect()
    }

    /// The actions' PHMMs for tracking, in order: as trained, or with the self-transitions
    /// capped by `cap` ([`DwellCap`]). Errors: a cap outside (0, 1].
    pub fn tracking_phmms(&self, cap: Option<DwellCap>) -> Result<Vec<Phmm>> {
        self.actions
            .iter()
            .map(|a| match cap {
                Some(c) if c.keep_last => a.phmm.with_max_self_transition_before_last(c.max_stay),
                Some(c) => a.phmm.with_max_self_transition(c.max_stay),
                None => Ok(a.phmm.clone()),
            })
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|e| Error::Config(format!("max_stay: {e}")))
    }

    /// [`ActionModel::tracking_phmms`] for an actor whose height differs from the
    /// demonstrators': with `height_scale = Some(s)`, every model's vertical outputs (the z of
    /// shoulder, elbow and fingertip in the actor frame, i.e. height relative to the shoulder)
    /// are multiplied by `s` ([`Phmm::with_output_scale`]), so a table that lies at `s` times
    /// the demonstrators' depth below the shoulder is where the generated hand lands. The
    /// factor is the actor's rest height over [`ActionModel::rest_height`]. Errors: a bad cap,
    /// or `s` not finite and positive.
    pub fn tracking_phmms_scaled(
        &self,
        cap: Option<DwellCap>,
        height_scale: Option<f64>,
    ) -> Result<Vec<Phmm>> {
        let phmms = self.tracking_phmms(cap)?;
        let Some(z) = height_scale else {
            return Ok(phmms);
        };
        let factors = [1.0, 1.0, z, 1.0, 1.0, z, 1.0, 1.0, z];
        phmms
            .iter()
            .map(|p| p.with_output_scale(&factors))
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|e| Error::Config(format!("height scale: {e}")))
    }

    /// The models' rest height: the mean over actions of the first state's mean fingertip z
    /// (actor frame: below the shoulder is negative) at the centre of the training targets, the
    /// demonstrators' average start pose with the hand at rest. The reference of
    /// [`ActionModel::tracking_phmms_scaled`]'s factor.
    pub fn rest_height(&self) -> f64 {
        let zs: Vec<f64> = self
            .actions
            .iter()
            .filter(|a| a.phmm.dim() == 9 && a.phmm.theta_dim() == 2)
            .map(|a| {
                let (centre, _) = a.phmm.theta_normalisation();
                a.phmm.mean(0, centre)[8]
            })
            .collect();
        if zs.is_empty() {
            return f64::NAN;
        }
        zs.iter().sum::<f64>() / zs.len() as f64
    }

    /// The action by name.
    pub fn action(&self, name: &str) -> Option<&Action> {
        self.actions.iter().find(|a| a.name == name)
    }

    /// The model as the JSON of a model file.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(&FileOut {
            format: FORMAT,
            version: VERSION,
            model: self,
        })
        .map_err(|e| Error::Config(format!("cannot serialise the model: {e}")))
    }

    /// Parses model-file JSON; `path` names errors.
    pub fn from_json(path: &Path, text: &str) -> Result<ActionModel> {
        let json_err = |e: &serde_json::Error| {
            Error::parse(path, e.line().max(1), format!("malformed model file: {e}"))
        };
        let header: FileHeader = serde_json::from_str(text).map_err(|e| json_err(&e))?;
        match header.format.as_deref() {
            Some(FORMAT) => {}
            Some(other) => {
                return Err(Error::parse(
                    path,
                    key_line(text, "format"),
                    format!("not an actrack model file (format `{other}`, expected `{FORMAT}`)"),
                ));
            }
            None => {
                return Err(Error::invalid(
                    path,
                    format!("not an actrack model file (no `format` field; expected `{FORMAT}`)"),
                ));
            }
        }
        match header.version {
            Some(serde_json::Value::Number(n)) if n.as_u64() == Some(u64::from(VERSION)) => {}
            Some(v) => {
                return Err(Error::parse(
                    path,
                    key_line(text, "version"),
                    format!(
                        "model file version {v} is not supported (this build of actrack reads \
                         version {VERSION}); retrain the model or use a matching actrack"
                    ),
                ));
            }
            None => return Err(Error::invalid(path, "model file has no `version` field")),
        }
        let file: FileIn = serde_json::from_str(text).map_err(|e| json_err(&e))?;
        let model = file.model;
        if model.actions.is_empty() {
            return Err(Error::invalid(path, "the model has no actions"));
        }
        for a in &model.actions {
            if a.phmm.dim() != 9 || a.phmm.theta_dim() != 2 {
                return Err(Error::invalid(
                    path,
                    format!(
                        "action `{}`: expected a parametric HMM over 9-D poses with 2-D θ, found \
                         {}-D poses and {}-D θ",
                        a.name,
                        a.phmm.dim(),
                        a.phmm.theta_dim()
                    ),
                ));
            }
            let ordered = (0..2).all(|k| {
                a.theta_min[k].is_finite()
                    && a.theta_max[k].is_finite()
                    && a.theta_min[k] <= a.theta_max[k]
            });
            if !ordered {
                return Err(Error::invalid(
                    path,
                    format!(
                        "action `{}`: theta_min {:?} and theta_max {:?} must be finite with \
                         theta_min ≤ theta_max in both components",
                        a.name, a.theta_min, a.theta_max
                    ),
                ));
            }
        }
        for (i, a) in model.actions.iter().enumerate() {
            if model.actions[..i].iter().any(|b| b.name == a.name) {
                return Err(Error::invalid(
                    path,
                    format!(
                        "action name `{}` appears twice: action names must be unique",
                        a.name
                    ),
                ));
            }
        }
        Ok(model)
    }

    /// Reads a model file.
    pub fn load(path: &Path) -> Result<ActionModel> {
        let bytes = std::fs::read(path).map_err(|e| Error::read(path, e))?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|_| Error::invalid(path, "not a model file (not UTF-8 text)"))?;
        ActionModel::from_json(path, text)
    }

    /// Writes a model file atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::mocap::write_atomic(path, self.to_json()?.as_bytes())
    }
}

/// 1-based line of the first `"key"` in JSON text (1 when absent): where a header field is.
fn key_line(text: &str, key: &str) -> usize {
    let needle = format!("\"{key}\"");
    text.find(&needle).map_or(1, |at| {
        1 + text[..at].bytes().filter(|&b| b == b'\n').count()
    })
}

/// Current UTC time as ISO 8601 (`2026-11-22T03:04:05Z`), from the system clock.
pub fn now_iso8601() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_date_shape() {
        let s = now_iso8601();
        assert_eq!(s.len(), 20, "{s}");
        assert!(s.starts_with("20") && s.ends_with('Z'));
    }

    #[test]
    fn header_errors() {
        let p = Path::new("m.actrack.json");
        let e = ActionModel::from_json(p, "{\"format\":\"actrack-model\",\"version\":2}")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("m.actrack.json") && e.contains("version 2"),
            "{e}"
        );
        let e = ActionModel::from_json(p, "{\"format\":\"other\"}")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not an actrack model"), "{e}");
        let e = ActionModel::from_json(p, "{\n\"format\": ")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("m.actrack.json:2:"), "{e}");
    }
}
