//! Training manifests (TOML): which trials, which action, which arm, which static trial, which θ,
//! and the training and preprocessing options.
//!
//! ```toml
//! # Paths are relative to `root`, itself relative to the directory of this manifest file
//! # (default "." = the manifest's directory).
//! root = ".."
//!
//! [options]            # all optional (defaults shown)
//! states = 20
//! max_jump = 3
//! iterations = 50
//! cov_floor = 0.001    # metres (σ_min)
//!
//! [preprocessing]      # all optional (defaults shown)
//! frame_rate = 30      # Hz, or "capture" to keep the capture rate
//! max_gap = 10         # frames interpolated
//! trim = { speed = 0.05, margin = 0 }   # m/s, or `false`
//! heading = "auto"     # or { degrees = 180 }
//! frame = "actor"      # or "lab" (the capture's coordinates, for comparison only)
//! theta = "max-extension"              # or "last-frame"
//!
//! [[trials]]
//! files = "../shared/data/ue-adl/ADL00[1-7]/ADL00?[FA]R?.csv.xz"  # a path, a pattern or a list
//! action = "reach"
//! arm = "R"                            # R or L (L is mirrored onto the right)
//! static = "{dir}/*_static.csv.xz"     # {dir} = the trial's directory; must match one file
//! # theta = [0.0, 0.65]                # optional explicit θ (actor frame, metres)
//! # theta_rule = "last-frame"          # optional per-entry rule
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use toml::Spanned;

use crate::error::{Error, Result};
use crate::mocap::ArmSide;
use crate::mocap::glob;
use crate::mocap::trial::{Preprocessing, ThetaRule};

/// Training options (the parametric HMM of each action).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainOptions {
    /// States per action model.
    pub states: usize,
    /// Maximum forward jump J.
    pub max_jump: usize,
    /// Maximum Baum–Welch iterations.
    pub iterations: usize,
    /// Covariance floor σ_min in metres.
    pub cov_floor: f64,
    /// Relative log-likelihood tolerance for convergence.
    pub tolerance: f64,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            states: 20,
            max_jump: 3,
            iterations: 50,
            cov_floor: 0.001,
            tolerance: 1e-4,
        }
    }
}

/// One or several file paths / patterns.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
enum Files {
    One(String),
    Many(Vec<String>),
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEntry {
    files: Spanned<Files>,
    action: String,
    #[serde(default = "default_arm")]
    arm: ArmSide,
    #[serde(default, rename = "static")]
    static_trial: Option<String>,
    #[serde(default)]
    theta: Option<[f64; 2]>,
    #[serde(default)]
    theta_rule: Option<ThetaRule>,
}

fn default_arm() -> ArmSide {
    ArmSide::Right
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawManifest {
    #[serde(default)]
    root: Option<String>,
    #[serde(default)]
    options: TrainOptions,
    #[serde(default)]
    preprocessing: Preprocessing,
    #[serde(default)]
    trials: Vec<RawEntry>,
}

/// A trial named by a manifest, with its files resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct ManifestTrial {
    /// The movement file.
    pub file: PathBuf,
    /// The subject's static trial (marker files).
    pub static_path: Option<PathBuf>,
    /// Action label.
    pub action: String,
    /// Acting arm.
    pub arm: ArmSide,
    /// Explicit θ.
    pub theta: Option<[f64; 2]>,
    /// Per-entry θ rule.
    pub theta_rule: Option<ThetaRule>,
    /// Line of the `[[trials]]` entry in the manifest.
    pub line: usize,
    /// The manifest that lists the trial (`None` for a trial given directly): errors about the
    /// entry itself, such as a missing `static`, name it and [`ManifestTrial::line`].
    pub manifest: Option<PathBuf>,
}

/// A parsed manifest.
#[derive(Clone, Debug)]
pub struct Manifest {
    /// The manifest file.
    pub path: PathBuf,
    /// The directory relative paths are resolved against.
    pub root: PathBuf,
    /// Training options.
    pub options: TrainOptions,
    /// Preprocessing options.
    pub preprocessing: Preprocessing,
    /// The trials, resolved (patterns expanded, static trials found), in manifest order.
    pub trials: Vec<ManifestTrial>,
}

impl Manifest {
    /// Reads, parses and resolves a manifest file.
    pub fn load(path: &Path) -> Result<Manifest> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
        Manifest::parse(path, &text)
    }

    /// Parses and resolves manifest text; `path` locates relative paths and names errors.
    pub fn parse(path: &Path, text: &str) -> Result<Manifest> {
        let raw: RawManifest = toml::from_str(text).map_err(|e| {
            let line = e.span().map_or(1, |s| line_of(text, s.start));
            Error::parse(path, line, e.message().to_string())
        })?;
        let base = path.parent().map_or_else(PathBuf::new, Path::to_path_buf);
        let root = match &raw.root {
            Some(r) => base.join(r),
            None => base,
        };
        if raw.trials.is_empty() {
            return Err(Error::invalid(
                path,
                "the manifest lists no trials (add [[trials]] entries)",
            ));
        }
        raw.options_check(path, text)?;
        let mut trials = Vec::new();
        for e in &raw.trials {
            let line = line_of(text, e.files.span().start);
            let patterns = match e.files.get_ref() {
                Files::One(s) => vec![s.clone()],
                Files::Many(v) => v.clone(),
            };
            if e.action.trim().is_empty() {
                return Err(Error::parse(path, line, "empty action label"));
            }
            for pat in patterns {
                let full = root.join(&pat);
                let files = glob::expand(&full);
                let files: Vec<PathBuf> = files.into_iter().filter(|f| f.is_file()).collect();
                if files.is_empty() {
                    return Err(Error::parse(
                        path,
                        line,
                        format!("`{pat}` matches no file (looked for {})", full.display()),
                    ));
                }
                for file in files {
                    let static_path = match &e.static_trial {
                        None => None,
                        Some(s) => Some(resolve_static(path, line, &root, &file, s)?),
                    };
                    trials.push(ManifestTrial {
                        file,
                        static_path,
                        action: e.action.trim().to_string(),
                        arm: e.arm,
                        theta: e.theta,
                        theta_rule: e.theta_rule,
                        line,
                        manifest: Some(path.to_path_buf()),
                    });
                }
            }
        }
        Ok(Manifest {
            path: path.to_path_buf(),
            root,
            options: raw.options,
            preprocessing: raw.preprocessing,
            trials,
        })
    }

    /// The distinct action labels in order of first appearance.
    pub fn actions(&self) -> Vec<String> {
        let mut v: Vec<String> = Vec::new();
        for t in &self.trials {
            if !v.contains(&t.action) {
                v.push(t.action.clone());
            }
        }
        v
    }
}

impl RawManifest {
    fn options_check(&self, path: &Path, text: &str) -> Result<()> {
        let line = text
            .lines()
            .position(|l| l.trim_start().starts_with("[options]"))
            .map_or(1, |k| k + 1);
        let o = &self.options;
        let bad = |m: String| Err(Error::parse(path, line, m));
        if o.states == 0 {
            return bad("options.states must be at least 1".into());
        }
        if o.max_jump == 0 {
            return bad("options.max_jump must be at least 1".into());
        }
        if !(o.cov_floor.is_finite() && o.cov_floor > 0.0) {
            return bad(format!(
                "options.cov_floor must be > 0 metres, not {}",
                o.cov_floor
            ));
        }
        self.preprocessing
            .check()
            .map_err(|e| Error::invalid(path, e.to_string()))
    }
}

fn resolve_static(
    manifest: &Path,
    line: usize,
    root: &Path,
    file: &Path,
    s: &str,
) -> Result<PathBuf> {
    let dir = file.parent().unwrap_or(Path::new("."));
    let p = if s.contains("{dir}") {
        PathBuf::from(s.replace("{dir}", &dir.to_string_lossy()))
    } else {
        root.join(s)
    };
    let found: Vec<PathBuf> = glob::expand(&p)
        .into_iter()
        .filter(|f| f.is_file())
        .collect();
    match found.len() {
        1 => Ok(found.into_iter().next().unwrap_or_default()),
        0 => Err(Error::parse(
            manifest,
            line,
            format!(
                "static trial `{s}` for {} not found (looked for {})",
                file.display(),
                p.display()
            ),
        )),
        n => Err(Error::parse(
            manifest,
            line,
            format!(
                "static trial `{s}` for {} matches {n} files; it must match one",
                file.display()
            ),
        )),
    }
}

fn line_of(text: &str, byte: usize) -> usize {
    text.as_bytes()
        .iter()
        .take(byte.min(text.len()))
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_resolves() {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("data/S1");
        std::fs::create_dir_all(&data).unwrap();
        for f in ["S1FR1.csv", "S1FR2.csv", "S1_static.csv"] {
            std::fs::write(data.join(f), "x").unwrap();
        }
        let m = dir.path().join("m/train.toml");
        std::fs::create_dir_all(m.parent().unwrap()).unwrap();
        let text = "root = \"..\"\n[options]\nstates = 7\n[preprocessing]\nframe_rate = \"capture\"\ntrim = false\n\n[[trials]]\nfiles = \"data/S*/S?FR?.csv\"\naction = \"reach\"\narm = \"L\"\nstatic = \"{dir}/*_static.csv\"\n";
        let man = Manifest::parse(&m, text).unwrap();
        assert_eq!(man.options.states, 7);
        assert_eq!(man.preprocessing.frame_rate, None);
        assert_eq!(man.preprocessing.trim, None);
        assert_eq!(man.trials.len(), 2);
        assert_eq!(man.trials[0].arm, ArmSide::Left);
        assert_eq!(man.trials[0].line, 9);
        assert!(
            man.trials[1]
                .static_path
                .as_ref()
                .unwrap()
                .ends_with("S1_static.csv")
        );

        let missing = text.replace("S?FR?", "S?XX?");
        let e = Manifest::parse(&m, &missing).unwrap_err().to_string();
        assert!(
            e.contains("train.toml:9") && e.contains("matches no file"),
            "{e}"
        );
        let nostatic = text.replace("*_static", "*_nope");
        let e = Manifest::parse(&m, &nostatic).unwrap_err().to_string();
        assert!(
            e.contains("train.toml:9") && e.contains("static trial"),
            "{e}"
        );
        let e = Manifest::parse(&m, "[options]\nstates = 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("no trials"), "{e}");
        let e = Manifest::parse(&m, "[options]\nstates = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("train.toml:3") || e.contains("train.toml:2"),
            "{e}"
        );
    }
}
