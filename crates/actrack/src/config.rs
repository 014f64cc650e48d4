//! [`TrackConfig`]: every choice that changes a track, in one validated, serialisable tree.
//!
//! A configuration is TOML with five tables — `[filter]`, `[prior]`, `[observation]`,
//! `[actor]` and `[output]` — and every key has a default: the `default` preset, the most
//! accurate configuration measured that meets the real-time budget (docs/results.md). A file
//! needs only the keys it changes. The presets ship in the repository's `presets/` directory
//! and are built into the library ([`TrackConfig::preset`]): `default`, and `paper`, the
//! method of SPEC.md exactly (for comparison).
//!
//! [`TrackConfig::check`] validates the values and names the offending key, so the tracker
//! ([`crate::Session`]) only ever sees a valid configuration. Single keys are overridden with
//! [`TrackConfig::set`] (`track --set filter.particles=800`).
//!
//! The fields' doc comments are the user's reference: [`schemars::JsonSchema`] carries them into
//! the configuration's JSON Schema, from which docs/configuration.md's table of keys is generated
//! (crates/actrack/tests/configuration_doc.rs). They say what a key does and why, for a user.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::model::DwellCap;

/// The presets that ship with the library: name and TOML text.
pub const PRESETS: [(&str, &str); 2] = [
    ("default", include_str!("../../../presets/default.toml")),
    ("paper", include_str!("../../../presets/paper.toml")),
];

/// The most particles a configuration may ask for (memory: a particle holds a pose and its
/// generator state, and the likelihood buffers grow with M).
pub const MAX_PARTICLES: usize = 1 << 20;

/// Every choice that changes a track.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TrackConfig {
    /// The particle filter in action space (SPEC §3).
    pub filter: FilterConfig,
    /// The prior over the actions' targets θ and the models (SPEC §3.2).
    pub prior: PriorConfig,
    /// The observation model: edge image and likelihood (SPEC §4).
    pub observation: ObservationConfig,
    /// What is known of the actor (not in the paper).
    pub actor: ActorConfig,
    /// What the outputs report (SPEC §3.7).
    pub output: OutputConfig,
}

/// The particle filter (SPEC §3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct FilterConfig {
    /// The number of particles M, in [1, 1048576]. More particles follow the arm more
    /// reliably, and each costs time in every frame.
    pub particles: usize,
    /// The seed of every random draw of the filter: the same seed, configuration and input give
    /// the same track, whatever the number of threads.
    pub seed: u64,
    /// σ(N)/σ(0), in (0, 1]: how much the diffusion of θ cools from a model's first state to its
    /// last (SPEC §3.3, decreasing as its erratum E1 reads it), so that θ settles as the action
    /// nears its target; 1 = no cooling.
    pub sigma_end_ratio: f64,
    /// The fraction ε ∈ [0, 1) of the particles split evenly over the actions at each
    /// resampling, whatever their posterior, so that a less probable action stays tracked and in
    /// phase; 0 resamples the joint set (SPEC §3.6 literally).
    pub action_floor: f64,
    /// The probability per frame, in [0, 0.5), that the action label changes: a Markov chain on
    /// the action, mixed into the carried action posterior when `action_floor` > 0 (not in the
    /// paper). Frames that carry little action information, such as the rest pose, then cannot
    /// rule an action out before its movement starts.
    pub action_switch: f64,
    /// A cap, in (0, 1], on every model state's self-transition probability (not in the paper):
    /// no state is expected to last longer than 1/(1 − max_stay) frames, so a subject who moves
    /// faster than the demonstrators is not left behind; 1 keeps the models' own dwell times.
    pub max_stay: f64,
    /// With `max_stay` < 1: each model's last state keeps its trained dwell, so a finished
    /// action stays finished (the demonstrations end at rest).
    pub keep_last_dwell: bool,
    /// A per-particle speed range `[s_min, s_max]`, 0 < s_min ≤ s_max, in model transitions per
    /// frame (not in the paper): each particle draws its speed log-uniformly per action
    /// instance, so that people faster or slower than the demonstrators are followed; `[]`:
    /// every particle follows the models' timing.
    pub speed_range: Vec<f64>,
}

/// The θ prior and the models.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PriorConfig {
    /// Where each action draws its target θ (SPEC §3.2).
    pub theta: ThetaPrior,
    /// The padding of the `training` θ prior around each action's training targets, metres, in
    /// [0, 10].
    pub theta_pad: f64,
    /// A factor (> 0) on the models' vertical outputs, for an actor whose table lies nearer to
    /// or farther from the shoulder than the demonstrators'; 1 keeps the models' heights.
    pub height_scale: f64,
}

/// The θ prior of every action.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ThetaPrior {
    /// The box of the action's own training targets, padded by `prior.theta_pad` and clipped to
    /// the scene's table region: a linear parametric HMM far outside its training targets
    /// generates implausible poses.
    #[default]
    Training,
    /// The scene's table region for every action (SPEC §3.2 literally).
    Scene,
}

/// The observation model (SPEC §4) and its extensions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ObservationConfig {
    /// How a pose's contour, the points its likelihood is scored on, is found.
    pub contour: Contour,
    /// γ of SPEC Eq. 3 for one view, > 0: log P(I | x̃) = −ε̄ / (2γ²), so a smaller γ sharpens
    /// the likelihood.
    pub gamma: f64,
    /// Scale γ by √V for V views: the views' errors add up, and without it every extra view
    /// sharpens the likelihood by another factor.
    pub gamma_sqrt_views: bool,
    /// The image gradient the edge map G is computed from.
    pub gradient: Gradient,
    /// The widest image the observation model works on, pixels: 0 or in [32, 100000] (not in
    /// the paper). A wider frame is shrunk by the smallest integer factor that brings it within
    /// this width (block means), and its camera with it, so the edge image, the gate and the
    /// likelihood cost the same for a 1280×720 camera as for a 640×360 one and see the arm at a
    /// similar scale. The foreground gate's `radius` and `margin` count pixels of the shrunk
    /// image; estimates stay in the world, and outputs keep the frame's size. 0 keeps every
    /// frame at its own size.
    pub max_width: u32,
    /// Where the edge image is computed (not in the paper).
    pub edge_region: EdgeRegion,
    /// The short-contour penalty, which replaces SPEC's mean error ε̄ (not in the paper).
    pub short_contour_penalty: PenaltyConfig,
    /// The local normalisation of G (not in SPEC §4.1).
    pub local_norm: LocalNormConfig,
    /// The foreground gate on G (not in SPEC §4.1).
    pub foreground_gate: GateConfig,
    /// Where the batch likelihood of the particles is computed.
    pub device: Device,
}

/// The contour method of the likelihood.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Contour {
    /// The inner boundary of the rasterised silhouette (SPEC §4.2, normative).
    Raster,
    /// Points every 2 px along each part's projected outline: much cheaper than rasterising.
    #[default]
    Analytic,
}

impl From<Contour> for actrack_render::ContourMethod {
    fn from(c: Contour) -> Self {
        match c {
            Contour::Raster => Self::Raster,
            Contour::Analytic => Self::Analytic,
        }
    }
}

/// Where the edge image G is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum EdgeRegion {
    /// Every pixel of the frame (SPEC §4.1): G is normalised by the maxima of the whole frame.
    Frame,
    /// The pixels the arms of the frame's particles project into, with the halo the Sobel
    /// and Gaussian filters need (not in the paper): the likelihood reads G nowhere else. The
    /// region follows the particles, so the cost of G, the gate and its normalisation follow
    /// the arm, not the frame; G is 0 elsewhere, and its maxima are the region's.
    #[default]
    Particles,
}

/// The image gradient the edge map is computed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Gradient {
    /// The Sobel magnitude of the grey image, 0.299 R + 0.587 G + 0.114 B (SPEC §4.1).
    Grey,
    /// Per pixel the largest Sobel magnitude of R, G and B (not in the paper), so that a
    /// boundary between two colours of the same brightness is an edge too.
    #[default]
    Colour,
}

/// Where the batch likelihood is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Device {
    /// The CPU, the particles spread over its threads.
    #[default]
    Cpu,
    /// wgpu compute shaders (feature `gpu`; analytic contours and SPEC's ε̄ only); an error
    /// when there is no adapter.
    Gpu,
    /// A hardware GPU when there is one, else the CPU (a software adapter is slower than the
    /// CPU path).
    Auto,
}

/// The short-contour penalty: a pose whose contour has n points, fewer than the q-quantile n̄
/// of the frame's particle set, counts each missing point with error λ:
/// ε = (Σ (1 − G)² + λ·max(0, n̄ − n)) / max(n, n̄). A mean over the contour (SPEC's ε̄) lets a
/// short, foreshortened contour win on a few strong edges of the torso.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PenaltyConfig {
    /// Replace SPEC's mean error ε̄ by the short-contour penalty: a pose whose contour has n
    /// points, fewer than the q-quantile n̄ of the frame's particle set, counts each missing
    /// point with error λ, ε = (Σ (1 − G)² + λ·max(0, n̄ − n)) / max(n, n̄). With the mean, a
    /// short, foreshortened contour wins on a few strong edges of the torso.
    pub enabled: bool,
    /// λ, in [0, 1]: the error each missing point of a short contour counts.
    pub weight: f64,
    /// q, in [0, 1]: the quantile of the frame's particle set's contour lengths that sets n̄,
    /// the length below which a contour counts missing points.
    pub quantile: f64,
}

/// The local normalisation of G: G / max(floor, max of G in a (2R + 1)² window).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct LocalNormConfig {
    /// Divide the edge image G by its local maximum, G / max(`floor`, max of G in the
    /// (2R + 1)² window around each pixel), so that weak but local edges count.
    pub enabled: bool,
    /// R, pixels, in [1, 10000]: the half-width of the window whose maximum divides G.
    pub radius: u32,
    /// The divisor's floor, in (0, 1]: weak edges far from any strong one are not raised to 1.
    pub floor: f32,
}

/// The foreground gate: a pixel is foreground where its grey value differs from the
/// background by more than `threshold`; the mask is dilated by `radius` and
/// G' = G · (floor + (1 − floor) · mask). The background starts from the first frame and after
/// each frame blends in B ← B + rate · (I − B) away from the tracked arm (`margin` pixels
/// around its silhouette), so the arm is not learnt as background while the track follows it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct GateConfig {
    /// Multiply the edge image G by a foreground mask against a background the tracker keeps,
    /// G' = G · (floor + (1 − floor) · mask), so that what does not move stops attracting the
    /// contour. The background starts from the first frame and learns from each frame away from
    /// the tracked arm.
    pub enabled: bool,
    /// The grey-level difference from the background, in [0, 255], above which a pixel is
    /// foreground.
    pub threshold: f32,
    /// The half-width of the square the foreground mask is dilated by, pixels of the image the
    /// observation works on (see `observation.max_width`), in [0, 10000].
    pub radius: u32,
    /// G's factor away from the foreground, in [0, 1]: 0 removes the edges there, 1 keeps them.
    pub floor: f32,
    /// The background's learning rate per frame, in (0, 1]: after each frame,
    /// B ← B + rate · (I − B) away from the tracked arm.
    pub rate: f32,
    /// The pixels (as `radius`) around the tracked silhouette that the background does not
    /// learn, in [0, 10000], so that the arm is not learnt as background while the track
    /// follows it.
    pub margin: f32,
}

/// What is known of the actor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ActorConfig {
    /// A soft floor under the fingertip, since the hand rests on the table and cannot go through
    /// it (not in the paper). In a monocular view a hand lower and nearer the body can lie on the
    /// same viewing ray as the true one; the floor rules out the part under the table.
    pub fingertip_floor: FloorSetting,
    /// The floor's softness σ, metres, > 0: a fingertip d below the floor loses ½(d/σ)² of
    /// log-likelihood.
    pub floor_sigma: f64,
}

/// Where the fingertip floor lies.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum FloorSetting {
    /// No floor.
    Off,
    /// The scene's table surface ([`crate::scene::Scene::table_height`]).
    #[default]
    Table,
    /// A height in metres in the actor frame (negative: below the shoulder), within ±10 m.
    Height(f64),
}

impl Serialize for FloorSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Self::Off => s.serialize_str("off"),
            Self::Table => s.serialize_str("table"),
            Self::Height(z) => s.serialize_f64(*z),
        }
    }
}

impl<'de> Deserialize<'de> for FloorSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Name(String),
            Number(f64),
            Int(i64),
        }
        match Raw::deserialize(d)? {
            Raw::Name(s) if s == "off" => Ok(Self::Off),
            Raw::Name(s) if s == "table" => Ok(Self::Table),
            Raw::Name(s) => Err(serde::de::Error::custom(format!(
                "expected `off`, `table` or a height in metres, got `{s}`"
            ))),
            Raw::Number(z) => Ok(Self::Height(z)),
            Raw::Int(z) => Ok(Self::Height(z as f64)),
        }
    }
}

/// The schema of the TOML form above: `"off"`, `"table"` or a number. Written by hand, as the
/// serde form is; its descriptions are the variants' doc comments.
impl JsonSchema for FloorSetting {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "FloorSetting".into()
    }

    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "Where the fingertip floor lies.",
            "oneOf": [
                { "type": "string", "const": "off", "description": "No floor." },
                {
                    "type": "string",
                    "const": "table",
                    "description": "The scene's table surface."
                },
                {
                    "type": "number",
                    "description": "A height in metres in the actor frame (negative: below the shoulder), within ±10 m."
                }
            ]
        })
    }
}

/// What the outputs report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// The median filter over time that gives the reported pose from the best particle's
    /// (SPEC §3.7).
    pub median: Median,
    /// W, the median's window in frames, in [1, 1001]; odd when centred.
    pub median_window: usize,
    /// The particles drawn per frame on the MCAP topic `/actrack/particles` (the θ cloud), at
    /// most 1000000: a systematic sample of the filter's particles, in which each action keeps
    /// its share; 0 leaves the cloud out. Writing every particle costs more than tracking it.
    pub mcap_particles: usize,
}

/// The kind of median filter of the reported pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Median {
    /// Frame t from frames t − W + 1 … t: known at once, for live video.
    Causal,
    /// Frame t from frames t − h … t + h, W = 2h + 1: each frame is reported h frames later,
    /// and the pose is more accurate.
    #[default]
    Centred,
}

// The defaults below are the `default` preset (presets/default.toml); a unit test checks
// that the two agree.

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            particles: 3200,
            seed: 0,
            sigma_end_ratio: 1.0 / 16.0,
            action_floor: 0.9,
            action_switch: 0.0,
            max_stay: 0.8,
            keep_last_dwell: true,
            speed_range: Vec::new(),
        }
    }
}

impl Default for PriorConfig {
    fn default() -> Self {
        Self {
            theta: ThetaPrior::Training,
            theta_pad: 0.05,
            height_scale: 1.0,
        }
    }
}

impl Default for ObservationConfig {
    fn default() -> Self {
        Self {
            contour: Contour::Analytic,
            gamma: 0.15,
            gamma_sqrt_views: true,
            gradient: Gradient::Colour,
            max_width: 640,
            edge_region: EdgeRegion::Particles,
            short_contour_penalty: PenaltyConfig::default(),
            local_norm: LocalNormConfig::default(),
            foreground_gate: GateConfig::default(),
            device: Device::Cpu,
        }
    }
}

impl Default for PenaltyConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            weight: 1.0,
            quantile: 0.5,
        }
    }
}

impl Default for LocalNormConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            radius: 24,
            floor: 0.1,
        }
    }
}

impl Default for GateConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            threshold: 10.0,
            radius: 2,
            floor: 0.1,
            rate: 0.1,
            margin: 8.0,
        }
    }
}

impl Default for ActorConfig {
    fn default() -> Self {
        Self {
            fingertip_floor: FloorSetting::Table,
            floor_sigma: 0.01,
        }
    }
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            median: Median::Centred,
            median_window: 7,
            mcap_particles: 400,
        }
    }
}

/// A `config key `k`: …` error.
fn bad(key: &str, msg: impl std::fmt::Display) -> Error {
    Error::Config(format!("config key `{key}`: {msg}"))
}

fn in_range(key: &str, v: f64, lo: f64, hi: f64, what: &str) -> Result<()> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(bad(key, format!("{what}, got {v}")))
    }
}

fn positive(key: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(bad(key, format!("must be a finite number > 0, got {v}")))
    }
}

impl TrackConfig {
    /// The preset called `name` (`default` or `paper`).
    ///
    /// # Errors
    /// [`Error::Config`] for an unknown name (listing the known ones).
    pub fn preset(name: &str) -> Result<Self> {
        let Some((_, text)) = PRESETS.iter().find(|(n, _)| *n == name) else {
            let known: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
            return Err(Error::Config(format!(
                "unknown preset `{name}` (known: {})",
                known.join(", ")
            )));
        };
        Self::parse(text, std::path::Path::new(&format!("presets/{name}.toml")))
    }

    /// Reads and checks a configuration file.
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
        Self::parse(&text, path)
    }

    /// Parses and checks configuration TOML (keys not given keep their defaults); `path` is used
    /// in messages.
    pub fn parse(text: &str, path: &std::path::Path) -> Result<Self> {
        let cfg: Self = toml::from_str(text).map_err(|e| {
            let line = e.span().map_or(1, |s| {
                text[..s.start.min(text.len())].matches('\n').count() + 1
            });
            Error::parse(path, line, e.message().to_string())
        })?;
        cfg.check()
            .map_err(|e| Error::invalid(path, e.to_string()))?;
        Ok(cfg)
    }

    /// The configuration as TOML (every key, so that a track can be reproduced from it).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# not serialisable: {e}\n"))
    }

    /// Sets one key from `key=value` text (`filter.particles=800`, `output.median="causal"`,
    /// `actor.fingertip_floor=off`): the value is read as TOML, else as a string. The result is
    /// checked.
    ///
    /// # Errors
    /// [`Error::Config`] naming the key when it is unknown, the value has the wrong type or is
    /// out of range.
    pub fn set(&mut self, assignment: &str) -> Result<()> {
        let Some((key, value)) = assignment.split_once('=') else {
            return Err(Error::Config(format!(
                "`{assignment}`: expected KEY=VALUE, e.g. filter.particles=800"
            )));
        };
        let key = key.trim();
        let value = value.trim();
        let parsed: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.trim_matches('"').to_string()));
        let mut tree = toml::Value::try_from(&*self)
            .map_err(|e| Error::Config(format!("configuration: {e}")))?;
        let parts: Vec<&str> = key.split('.').collect();
        // Check the path first, so that an unknown key names what is known beside it.
        let mut node = &tree;
        for part in &parts {
            let table = node
                .as_table()
                .ok_or_else(|| bad(key, "not a table of the configuration"))?;
            node = table.get(*part).ok_or_else(|| {
                let known: Vec<&str> = table.keys().map(String::as_str).collect();
                bad(
                    key,
                    format!("unknown key `{part}` (known here: {})", known.join(", ")),
                )
            })?;
        }
        if node.is_table() {
            return Err(bad(key, "is a table; set one of its keys"));
        }
        // An integer where a float is expected is what the user means.
        let value = match (node, parsed) {
            (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(i as f64),
            (_, v) => v,
        };
        let mut slot = &mut tree;
        for part in &parts {
            let Some(next) = slot.as_table_mut().and_then(|t| t.get_mut(*part)) else {
                return Err(bad(key, "not a key of the configuration"));
            };
            slot = next;
        }
        *slot = value;
        let cfg: Self = tree
            .try_into()
            .map_err(|e: toml::de::Error| bad(key, e.message()))?;
        cfg.check()?;
        *self = cfg;
        Ok(())
    }

    /// Checks every value.
    ///
    /// # Errors
    /// [`Error::Config`] naming the first offending key and its value.
    pub fn check(&self) -> Result<()> {
        let f = &self.filter;
        if f.particles == 0 || f.particles > MAX_PARTICLES {
            return Err(bad(
                "filter.particles",
                format!("must be in [1, {MAX_PARTICLES}], got {}", f.particles),
            ));
        }
        in_range(
            "filter.sigma_end_ratio",
            f.sigma_end_ratio,
            f64::MIN_POSITIVE,
            1.0,
            "must be in (0, 1]",
        )?;
        if !(f.action_floor.is_finite() && (0.0..1.0).contains(&f.action_floor)) {
            return Err(bad(
                "filter.action_floor",
                format!("must be in [0, 1), got {}", f.action_floor),
            ));
        }
        if !(f.action_switch.is_finite() && (0.0..0.5).contains(&f.action_switch)) {
            return Err(bad(
                "filter.action_switch",
                format!("must be in [0, 0.5), got {}", f.action_switch),
            ));
        }
        in_range(
            "filter.max_stay",
            f.max_stay,
            f64::MIN_POSITIVE,
            1.0,
            "a probability in (0, 1]",
        )?;
        match f.speed_range.as_slice() {
            [] => {}
            &[lo, hi] if lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo => {}
            other => {
                return Err(bad(
                    "filter.speed_range",
                    format!("must be [] or [s_min, s_max] with 0 < s_min ≤ s_max, got {other:?}"),
                ));
            }
        }
        let p = &self.prior;
        in_range(
            "prior.theta_pad",
            p.theta_pad,
            0.0,
            10.0,
            "must be in [0, 10] metres",
        )?;
        positive("prior.height_scale", p.height_scale)?;
        let o = &self.observation;
        positive("observation.gamma", o.gamma)?;
        let pen = &o.short_contour_penalty;
        in_range(
            "observation.short_contour_penalty.weight",
            pen.weight,
            0.0,
            1.0,
            "must be in [0, 1]",
        )?;
        in_range(
            "observation.short_contour_penalty.quantile",
            pen.quantile,
            0.0,
            1.0,
            "a probability in [0, 1]",
        )?;
        let ln = &o.local_norm;
        if ln.radius == 0 || ln.radius > 10_000 {
            return Err(bad(
                "observation.local_norm.radius",
                format!("must be in [1, 10000] px, got {}", ln.radius),
            ));
        }
        in_range(
            "observation.local_norm.floor",
            f64::from(ln.floor),
            f64::MIN_POSITIVE,
            1.0,
            "must be in (0, 1]",
        )?;
        if o.max_width != 0 && !(32..=100_000).contains(&o.max_width) {
            return Err(bad(
                "observation.max_width",
                format!(
                    "must be 0 (full size) or in [32, 100000] px, got {}",
                    o.max_width
                ),
            ));
        }
        let g = &o.foreground_gate;
        in_range(
            "observation.foreground_gate.threshold",
            f64::from(g.threshold),
            0.0,
            255.0,
            "must be in [0, 255] grey levels",
        )?;
        if g.radius > 10_000 {
            return Err(bad(
                "observation.foreground_gate.radius",
                format!("must be in [0, 10000] px, got {}", g.radius),
            ));
        }
        in_range(
            "observation.foreground_gate.floor",
            f64::from(g.floor),
            0.0,
            1.0,
            "must be in [0, 1]",
        )?;
        in_range(
            "observation.foreground_gate.rate",
            f64::from(g.rate),
            f64::MIN_POSITIVE,
            1.0,
            "must be in (0, 1]",
        )?;
        in_range(
            "observation.foreground_gate.margin",
            f64::from(g.margin),
            0.0,
            10_000.0,
            "must be in [0, 10000] px",
        )?;
        if o.device == Device::Gpu {
            if o.contour != Contour::Analytic {
                return Err(bad(
                    "observation.device",
                    "the GPU scores analytic contours only (set observation.contour=\"analytic\")",
                ));
            }
            if pen.enabled {
                return Err(bad(
                    "observation.device",
                    "the GPU scores SPEC's ε̄ only (set \
                     observation.short_contour_penalty.enabled=false)",
                ));
            }
        }
        let a = &self.actor;
        if let FloorSetting::Height(z) = a.fingertip_floor
            && !(z.is_finite() && z.abs() <= 10.0)
        {
            return Err(bad(
                "actor.fingertip_floor",
                format!("a height must be within ±10 m of the shoulder, got {z}"),
            ));
        }
        positive("actor.floor_sigma", a.floor_sigma)?;
        let out = &self.output;
        if out.median_window == 0 || out.median_window > 1001 {
            return Err(bad(
                "output.median_window",
                format!("must be in [1, 1001] frames, got {}", out.median_window),
            ));
        }
        if out.mcap_particles > 1_000_000 {
            return Err(bad(
                "output.mcap_particles",
                format!("must be at most 1000000, got {}", out.mcap_particles),
            ));
        }
        if out.median == Median::Centred && out.median_window.is_multiple_of(2) {
            return Err(bad(
                "output.median_window",
                format!(
                    "a centred median needs an odd window (frames t − h … t + h), got {}",
                    out.median_window
                ),
            ));
        }
        Ok(())
    }

    /// The dwell cap of the models ([`crate::model::ActionModel::tracking_phmms`]); `None`
    /// when `filter.max_stay` is 1.
    pub fn dwell_cap(&self) -> Option<DwellCap> {
        (self.filter.max_stay < 1.0).then_some(DwellCap {
            max_stay: self.filter.max_stay,
            keep_last: self.filter.keep_last_dwell,
        })
    }

    /// The speed range of the filter, if any.
    pub fn speed_range(&self) -> Option<[f64; 2]> {
        match self.filter.speed_range.as_slice() {
            &[lo, hi] => Some([lo, hi]),
            _ => None,
        }
    }

    /// γ for `views` cameras.
    pub fn gamma(&self, views: usize) -> f64 {
        let o = &self.observation;
        if o.gamma_sqrt_views {
            o.gamma * (views.max(1) as f64).sqrt()
        } else {
            o.gamma
        }
    }

    /// The configuration as `# `-prefixed comment lines (the CSV header's).
    pub fn to_comment(&self) -> String {
        let mut s = String::from("# actrack track configuration (TrackConfig, TOML)\n");
        for line in self.to_toml().lines() {
            if line.trim().is_empty() {
                continue;
            }
            s.push_str("# ");
            s.push_str(line);
            s.push('\n');
        }
        s
    }

    /// Reads the configuration back from a CSV's comment lines ([`TrackConfig::to_comment`]);
    /// `None` when the text has none.
    pub fn from_comment(text: &str) -> Option<Result<Self>> {
        let body: Vec<&str> = text
            .lines()
            .take_while(|l| l.starts_with('#'))
            .skip(1)
            .map(|l| l.strip_prefix("# ").unwrap_or(l.trim_start_matches('#')))
            .collect();
        if body.is_empty() {
            return None;
        }
        Some(Self::parse(
            &body.join("\n"),
            std::path::Path::new("<csv header>"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_preset_is_the_default() {
        assert_eq!(
            TrackConfig::preset("default").unwrap(),
            TrackConfig::default()
        );
    }

    #[test]
    fn the_paper_preset_is_specs_method() {
        let p = TrackConfig::preset("paper").unwrap();
        assert_eq!(p.filter.particles, 400);
        assert_eq!(p.observation.contour, Contour::Raster);
        assert!(!p.observation.short_contour_penalty.enabled);
        assert!(!p.observation.foreground_gate.enabled);
        assert_eq!(p.actor.fingertip_floor, FloorSetting::Off);
        assert!(p.dwell_cap().is_none());
        assert_eq!(p.prior.theta, ThetaPrior::Scene);
        assert_eq!(p.output.median, Median::Causal);
        assert_eq!(p.output.median_window, 5);
    }

    #[test]
    fn toml_round_trips() {
        for (name, _) in PRESETS {
            let c = TrackConfig::preset(name).unwrap();
            let back = TrackConfig::parse(&c.to_toml(), std::path::Path::new("x")).unwrap();
            assert_eq!(back, c, "{name}");
            let again = TrackConfig::from_comment(&c.to_comment()).unwrap().unwrap();
            assert_eq!(again, c, "{name}");
        }
    }

    #[test]
    fn set_changes_one_key() {
        let mut c = TrackConfig::default();
        c.set("filter.particles=800").unwrap();
        c.set("output.median=causal").unwrap();
        c.set("output.median_window=5").unwrap();
        c.set("actor.fingertip_floor=-0.3").unwrap();
        c.set("observation.gamma=1").unwrap();
        assert_eq!(c.filter.particles, 800);
        assert_eq!(c.output.median, Median::Causal);
        assert_eq!(c.actor.fingertip_floor, FloorSetting::Height(-0.3));
        assert!((c.observation.gamma - 1.0).abs() < 1e-12);
        c.set("actor.fingertip_floor=off").unwrap();
        assert_eq!(c.actor.fingertip_floor, FloorSetting::Off);
    }

    #[test]
    fn bad_values_name_their_key() {
        let cases = [
            ("filter.particles=0", "filter.particles"),
            ("filter.particles=-5", "filter.particles"),
            ("observation.gamma=0", "observation.gamma"),
            ("observation.gamma=-1.5", "observation.gamma"),
            ("actor.floor_sigma=0", "actor.floor_sigma"),
            ("filter.action_floor=1.5", "filter.action_floor"),
            ("filter.max_stay=-0.1", "filter.max_stay"),
            ("observation.short_contour_penalty.quantile=2", "quantile"),
            (
                "observation.foreground_gate.floor=1.2",
                "foreground_gate.floor",
            ),
            ("filter.nonsense=3", "nonsense"),
            ("output.median_window=4", "output.median_window"),
            ("filter=3", "filter"),
        ];
        for (set, needle) in cases {
            let mut c = TrackConfig::default();
            let e = c.set(set).expect_err(set).to_string();
            assert!(e.contains(needle), "{set}: {e}");
            assert_eq!(
                c,
                TrackConfig::default(),
                "{set} left the configuration alone"
            );
        }
    }

    #[test]
    fn unknown_keys_in_a_file_are_errors_with_a_line() {
        let e = TrackConfig::parse(
            "[filter]\nparticles = 10\nparticels = 3\n",
            "c.toml".as_ref(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("c.toml:3") && e.contains("particels"), "{e}");
        let e = TrackConfig::parse("[filter]\nparticles = 0\n", "c.toml".as_ref())
            .unwrap_err()
            .to_string();
        assert!(e.contains("filter.particles"), "{e}");
        let e = TrackConfig::parse("[actor]\nfingertip_floor = \"floor\"\n", "c.toml".as_ref())
            .unwrap_err()
            .to_string();
        assert!(e.contains("c.toml:2"), "{e}");
    }

    #[test]
    fn a_partial_file_keeps_the_defaults() {
        let c = TrackConfig::parse("[filter]\nparticles = 10\n", "c.toml".as_ref()).unwrap();
        assert_eq!(c.filter.particles, 10);
        assert_eq!(c.observation, ObservationConfig::default());
    }
}
