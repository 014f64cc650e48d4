//! The tracking configuration on the command line, shared by `track` and `bench`:
//! `--config FILE | --preset NAME`, `--set KEY=VALUE …`, `--particles N`.

use std::path::PathBuf;

use actrack::TrackConfig;

/// The configuration options of `track` and `bench`.
#[derive(Debug, clap::Args)]
pub struct ConfigArgs {
    /// A tracking configuration file (TOML, `TrackConfig`: keys not given keep the defaults;
    /// docs/configuration.md lists every key).
    #[arg(long, value_name = "FILE", conflicts_with = "preset")]
    pub config: Option<PathBuf>,
    /// A configuration shipped with actrack: `default` (the most accurate measured; what
    /// `track` runs without --config) or `paper` (the paper's method exactly, for comparison).
    #[arg(long, value_name = "NAME")]
    pub preset: Option<String>,
    /// Override one configuration key, e.g. `--set filter.particles=800` or
    /// `--set output.median=causal` (repeatable; applied after --config / --preset).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Number of particles (the key `filter.particles`).
    #[arg(long)]
    pub particles: Option<usize>,
}

impl ConfigArgs {
    /// The configuration: `--config` or `--preset` (else the default), then `extra` (keys the
    /// command sets itself), `--set`, `--particles` and `seed`. A bad file, key or value is a
    /// usage error naming it.
    pub fn build(&self, extra: &[String], seed: Option<u64>) -> anyhow::Result<TrackConfig> {
        let mut set = extra.to_vec();
        set.extend(self.set.iter().cloned());
        build(
            self.config.as_deref(),
            self.preset.as_deref(),
            &set,
            self.particles,
            seed,
        )
    }
}

/// The configuration of `config` or `preset` (else the default), then `set`, `particles` and
/// `seed`.
pub fn build(
    config: Option<&std::path::Path>,
    preset: Option<&str>,
    set: &[String],
    particles: Option<usize>,
    seed: Option<u64>,
) -> anyhow::Result<TrackConfig> {
    let usage = |e: actrack::Error| super::UsageError(e.to_string());
    let mut cfg = match (config, preset) {
        (Some(p), _) => TrackConfig::load(p).map_err(usage)?,
        (None, Some(name)) => TrackConfig::preset(name).map_err(usage)?,
        (None, None) => TrackConfig::default(),
    };
    let mut overrides: Vec<String> = set.to_vec();
    if let Some(m) = particles {
        overrides.push(format!("filter.particles={m}"));
    }
    if let Some(s) = seed {
        overrides.push(format!("filter.seed={s}"));
    }
    for kv in &overrides {
        cfg.set(kv)
            .map_err(|e| super::UsageError(format!("--set {kv}: {e}")))?;
    }
    Ok(cfg)
}
