//! Randomised scene styles: what real footage varies in, drawn per video from a seed, so that
//! methods and parameters are chosen on many looks instead of one.
//!
//! A [`Style`] holds the camera (placement around the actor, field of view, resolution, lens
//! distortion), the appearance of the scene (colours with low-contrast cases, lighting and
//! shading, textured table and background, a torso and head that sway, the other arm, cups on
//! the table, clutter) and what the recording does to the frames (motion blur, sensor noise,
//! JPEG compression, dropped frames). [`Style::random`] draws one from a seed; the same seed
//! gives the same style and the same frames. [`StyledVideo`] renders a video's frames in it.

use actrack_render::synth::{Appearance, Cup, SceneSynth, SynthCache, TablePattern};
use image::RgbImage;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::scene::{Scene, SceneCamera, look_at};
use crate::synth::scene_synth;

/// Where the camera is, in the actor's frame, and what it is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraStyle {
    /// Direction from the workspace's centre to the camera, degrees about the vertical: 0 is in
    /// front of the actor (across the table, looking back), positive towards the actor's right.
    pub azimuth_deg: f64,
    /// Elevation of the camera above the workspace's centre, degrees.
    pub elevation_deg: f64,
    /// Distance from the workspace's centre, metres.
    pub distance: f64,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Brown distortion `[k1, k2, p1, p2, k3]` (OpenCV order).
    pub distortion: [f64; 5],
}

/// A video's look: camera, appearance and recording (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Style {
    /// The seed the style was drawn from; it also seeds the background, the clutter and the
    /// noise of the frames.
    pub seed: u64,
    /// The camera.
    pub camera: CameraStyle,
    /// Sleeve and torso colour.
    pub shirt_color: [u8; 3],
    /// Skin colour.
    pub skin_color: [u8; 3],
    /// Table colour.
    pub table_color: [u8; 3],
    /// Clutter shapes in the background.
    pub clutter: usize,
    /// Sensor noise σ, grey levels.
    pub noise_sigma: f64,
    /// Lighting, shading, textures, sway and the other arm.
    pub appearance: Appearance,
    /// Cups standing on the table, (u, v) in the actor frame, metres.
    pub cups: Vec<[f64; 2]>,
    /// Whether a drink's cup is drawn at its target and carried by the hand.
    pub drink_cup: bool,
    /// Poses per exposure: 1 is a sharp frame, more blur the arm along its motion.
    pub blur: usize,
    /// JPEG quality the frames are compressed with (`None`: lossless).
    pub jpeg_quality: Option<u8>,
    /// Fraction of frames the camera drops: a dropped frame repeats the previous one.
    pub drop_rate: f64,
}

/// Frame sizes a random style picks from.
pub const SIZES: [(u32, u32); 5] = [(320, 240), (640, 360), (640, 480), (960, 540), (1280, 720)];

/// Radius of the part of the scene the camera frames around the workspace's centre, metres.
const FRAMED_RADIUS: f64 = 0.55;

fn hsv(h: f64, s: f64, v: f64) -> [u8; 3] {
    let c = v * s;
    let hp = (h.rem_euclid(360.0)) / 60.0;
    let x = c * (1.0 - (hp % 2.0 - 1.0).abs());
    let (r, g, b) = match hp as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    [r, g, b].map(|u| ((u + m) * 255.0).round().clamp(0.0, 255.0) as u8)
}

fn jitter(c: [u8; 3], by: f64, rng: &mut Pcg64Mcg) -> [u8; 3] {
    c.map(|v| (f64::from(v) + rng.random_range(-by..=by)).clamp(0.0, 255.0) as u8)
}

impl Style {
    /// The look of `synth`'s classic scenes with a given camera: no blur, compression, drops,
    /// cups or sway.
    pub fn classic(seed: u64, camera: CameraStyle) -> Self {
        Self {
            seed,
            camera,
            shirt_color: [40, 70, 150],
            skin_color: [225, 170, 140],
            table_color: [165, 120, 75],
            clutter: 40,
            noise_sigma: 3.0,
            appearance: Appearance::default(),
            cups: Vec::new(),
            drink_cup: false,
            blur: 1,
            jpeg_quality: None,
            drop_rate: 0.0,
        }
    }

    /// A style drawn from `seed`: every setting from a wide range of what real footage shows
    /// (cameras on both sides of the actor and in front of them, 320×240 to 1280×720, lens
    /// distortion, skin tones from light to dark, low-contrast sleeves, patterned tables, hard
    /// and soft light, compression, blur, noise and dropped frames).
    pub fn random(seed: u64) -> Self {
        let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x5a17_e5ee_d000_0001);
        let (width, height) = SIZES[rng.random_range(0..SIZES.len())];
        let hfov_deg: f64 = rng.random_range(45.0..80.0);
        // Far enough that the workspace fits the narrower of the two fields of view.
        let half = (hfov_deg / 2.0).to_radians().tan() * f64::from(height) / f64::from(width);
        let distance = rng.random_range(1.2..1.9) * FRAMED_RADIUS / half;
        let distortion = if rng.random_bool(0.35) {
            [0.0; 5]
        } else {
            let k1: f64 = rng.random_range(-0.3..0.08);
            [
                k1,
                rng.random_range(-0.05..0.12) * k1.abs() / 0.3,
                rng.random_range(-0.002..0.002),
                rng.random_range(-0.002..0.002),
                0.0,
            ]
        };
        let camera = CameraStyle {
            azimuth_deg: rng.random_range(-110.0..110.0),
            elevation_deg: rng.random_range(12.0..55.0),
            distance,
            hfov_deg,
            width,
            height,
            distortion,
        };
        // Skin tones from light to dark; sleeves of any hue, pale to saturated.
        let skins = [
            [241, 194, 167],
            [224, 172, 138],
            [198, 145, 105],
            [161, 110, 75],
            [120, 80, 55],
            [85, 58, 42],
        ];
        let skin_color = jitter(skins[rng.random_range(0..skins.len())], 10.0, &mut rng);
        let shirt_color = hsv(
            rng.random_range(0.0..360.0),
            rng.random_range(0.1..0.85),
            rng.random_range(0.15..0.95),
        );
        let tables = [
            [165, 120, 75],
            [205, 200, 190],
            [120, 120, 125],
            [70, 50, 35],
            [235, 235, 230],
        ];
        let mut table_color = jitter(tables[rng.random_range(0..tables.len())], 15.0, &mut rng);
        // Low-contrast cases: the sleeve against the wall, the skin against the table.
        let background = if rng.random_bool(0.25) {
            Some(jitter(shirt_color, 25.0, &mut rng))
        } else {
            None
        };
        if rng.random_bool(0.2) {
            table_color = jitter(skin_color, 20.0, &mut rng);
        }
        let appearance = Appearance {
            shading: rng.random_range(0.3..1.7),
            light_angle: if rng.random_bool(0.8) {
                Some(rng.random_range(0.0..std::f64::consts::TAU))
            } else {
                None
            },
            background,
            texture: rng.random_range(2.0..20.0),
            table_pattern: [
                TablePattern::Grain,
                TablePattern::Plain,
                TablePattern::Checker,
            ][rng.random_range(0..3)],
            sway: rng.random_range(0.0..0.03),
            other_arm: rng.random_bool(0.6),
            gain: rng.random_range(0.7..1.25),
            vignette: rng.random_range(0.0..0.4),
        };
        let cups = (0..rng.random_range(0..=3))
            .map(|_| [rng.random_range(-0.45..0.45), rng.random_range(0.25..0.6)])
            .collect();
        Self {
            seed,
            camera,
            shirt_color,
            skin_color,
            table_color,
            clutter: rng.random_range(0..100),
            noise_sigma: rng.random_range(1.0..8.0),
            appearance,
            cups,
            drink_cup: rng.random_bool(0.8),
            blur: rng.random_range(1..=3),
            jpeg_quality: if rng.random_bool(0.7) {
                Some(rng.random_range(25..=90))
            } else {
                None
            },
            drop_rate: if rng.random_bool(0.5) {
                0.0
            } else {
                rng.random_range(0.02..0.1)
            },
        }
    }

    /// Checks the settings are usable (sizes, angles, probabilities, finite numbers).
    ///
    /// # Errors
    /// [`Error::Config`] naming the setting.
    pub fn check(&self) -> Result<()> {
        let c = &self.camera;
        let bad = |what: &str| Err(Error::Config(format!("style: {what}")));
        if !(c.width >= 32
            && c.height >= 32
            && u64::from(c.width) * u64::from(c.height) <= 7680 * 4320)
        {
            return bad(&format!(
                "camera size {}x{} is outside 32x32 … 7680x4320",
                c.width, c.height
            ));
        }
        if !(c.hfov_deg > 1.0 && c.hfov_deg < 170.0) {
            return bad(&format!(
                "camera.hfov_deg = {} is not in (1, 170)",
                c.hfov_deg
            ));
        }
        if !(c.distance > 0.2 && c.distance < 100.0) {
            return bad(&format!(
                "camera.distance = {} m is not in (0.2, 100)",
                c.distance
            ));
        }
        if !(c.elevation_deg > -80.0 && c.elevation_deg < 89.0 && c.azimuth_deg.is_finite()) {
            return bad("camera elevation must be in (-80, 89) degrees and the azimuth finite");
        }
        if !c.distortion.iter().all(|d| d.is_finite() && d.abs() < 10.0) {
            return bad("camera.distortion must be five finite coefficients");
        }
        if !(1..=16).contains(&self.blur) {
            return bad(&format!("blur = {} is not in 1 … 16", self.blur));
        }
        if !(0.0..0.9).contains(&self.drop_rate) {
            return bad(&format!(
                "drop_rate = {} is not in [0, 0.9)",
                self.drop_rate
            ));
        }
        if self.jpeg_quality.is_some_and(|q| !(1..=100).contains(&q)) {
            return bad("jpeg_quality must be in 1 … 100");
        }
        if !(self.noise_sigma >= 0.0 && self.noise_sigma < 100.0) {
            return bad(&format!(
                "noise_sigma = {} is not in [0, 100)",
                self.noise_sigma
            ));
        }
        let a = &self.appearance;
        if ![a.shading, a.texture, a.sway, a.gain, a.vignette]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0)
        {
            return bad(
                "appearance: shading, texture, sway, gain and vignette must be finite and ≥ 0",
            );
        }
        if !self.cups.iter().flatten().all(|v| v.is_finite()) {
            return bad("cups must be finite positions");
        }
        Ok(())
    }

    /// Reads a style from TOML (as [`Style::to_toml`] writes it).
    ///
    /// # Errors
    /// [`Error::Invalid`] naming the file, [`Error::Config`] for unusable settings.
    pub fn parse(text: &str, path: &std::path::Path) -> Result<Self> {
        let s: Self =
            toml::from_str(text).map_err(|e| Error::invalid(path, e.message().to_string()))?;
        s.check()?;
        Ok(s)
    }

    /// The style as TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// The camera of this style placed in `scene`: it looks at the workspace's centre (half way
    /// from the shoulder to the table region's centre) from the style's azimuth, elevation and
    /// distance.
    ///
    /// # Errors
    /// [`Error::Config`] if the camera cannot look at the workspace (a degenerate direction).
    pub fn camera_in(&self, scene: &Scene) -> Result<SceneCamera> {
        let c = &self.camera;
        let (centre, _) = scene.theta_region();
        let table_z = scene.table_height();
        let target = Vector3::new(0.5 * centre[0], 0.5 * centre[1], 0.5 * table_z);
        let (az, el) = (c.azimuth_deg.to_radians(), c.elevation_deg.to_radians());
        let eye =
            target + c.distance * Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
        let (eye, target) = (scene.actor.to_world(&eye), scene.actor.to_world(&target));
        let pose = look_at(eye, target, Vector3::z())
            .ok_or_else(|| Error::Config("style: the camera looks straight down".into()))?;
        let f = f64::from(c.width) / 2.0 / (c.hfov_deg.to_radians() / 2.0).tan();
        let mut cam = SceneCamera::centred("camera0", (c.width, c.height), f, pose);
        cam.model.distortion = c.distortion;
        Ok(cam)
    }

    /// `scene` seen through this style's camera (the only camera).
    ///
    /// # Errors
    /// As [`Style::camera_in`].
    pub fn scene(&self, scene: &Scene) -> Result<Scene> {
        let mut s = scene.clone();
        s.cameras = vec![self.camera_in(scene)?];
        Ok(s)
    }

    /// Whether frame `k` is dropped (it repeats frame `k − 1`); frame 0 never is.
    pub fn dropped(&self, k: usize) -> bool {
        if k == 0 || self.drop_rate <= 0.0 {
            return false;
        }
        let h = splitmix(self.seed ^ 0xd209_0000 ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        (h >> 11) as f64 / (1u64 << 53) as f64 <= self.drop_rate
    }
}

fn splitmix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Size of the cups the styles draw: radius and height, metres.
pub const CUP: (f64, f64) = (0.04, 0.10);

/// A drink's cup, per frame of a movement: it stands on the table at the target `theta_world`
/// (nudged away from the hand), is picked up when the fingertip first comes within 6 cm of it
/// and put back when the fingertip is last within 6 cm of where it stood; in between it moves
/// with the fingertip, never below the table.
pub fn carried_cup(
    poses_world: &[[f64; 9]],
    theta_world: Vector3<f64>,
    color: [u8; 3],
) -> Vec<Cup> {
    let tip = |p: &[f64; 9]| Vector3::new(p[6], p[7], p[8]);
    let table_z = theta_world.z;
    // Where the hand points at its closest approach: the cup stands just beyond the fingertip.
    let closest = poses_world.iter().min_by(|a, b| {
        (tip(a) - theta_world)
            .norm()
            .total_cmp(&(tip(b) - theta_world).norm())
    });
    let dir = closest.map_or_else(Vector3::zeros, |p| {
        Vector3::new(p[6] - p[3], p[7] - p[4], 0.0)
            .try_normalize(1e-9)
            .unwrap_or_else(Vector3::zeros)
    });
    let home = theta_world + dir * (CUP.0 + 0.01);
    let near = |p: &[f64; 9]| (tip(p) - home).norm() < 0.06 + CUP.0;
    let first = poses_world.iter().position(near);
    let last = poses_world.iter().rposition(near);
    let cup = |base: Vector3<f64>| Cup {
        base: [base.x, base.y, base.z.max(table_z)],
        radius: CUP.0,
        height: CUP.1,
        color,
    };
    let (Some(g), Some(r)) = (first, last) else {
        return vec![cup(home); poses_world.len()];
    };
    let offset = home - tip(&poses_world[g]);
    (0..poses_world.len())
        .map(|k| {
            if k < g || k > r {
                cup(home)
            } else {
                cup(tip(&poses_world[k]) + offset)
            }
        })
        .collect()
}

/// Renders a video's frames in a [`Style`]: the scene's first camera (set it with
/// [`Style::scene`]), the style's appearance, motion blur, JPEG compression and dropped frames.
/// Frames can be rendered in any order and in parallel (one [`SynthCache`] per thread): frame
/// `k` depends only on the style, the poses up to `k` and `k`'s cups.
#[derive(Clone, Debug)]
pub struct StyledVideo {
    style: Style,
    synth: SceneSynth,
    camera: actrack_render::Camera,
}

impl StyledVideo {
    /// A renderer of `scene` (its first camera) in `style`, with the arm of `lengths`.
    ///
    /// # Errors
    /// [`Error::Config`] for a scene without cameras or an unusable style.
    pub fn new(style: &Style, scene: &Scene, lengths: [f64; 2]) -> Result<Self> {
        style.check()?;
        let camera = scene
            .cameras
            .first()
            .ok_or_else(|| Error::Config("style: the scene has no camera".into()))?
            .model
            .clone();
        let mut synth = scene_synth(scene, lengths);
        synth.shirt_color = style.shirt_color;
        synth.skin_color = style.skin_color;
        synth.table_color = style.table_color;
        synth.clutter = style.clutter;
        synth.noise_sigma = style.noise_sigma;
        synth.appearance = style.appearance.clone();
        Ok(Self {
            style: style.clone(),
            synth,
            camera,
        })
    }

    /// The style's cups standing on the table, world frame.
    pub fn table_cups(&self, scene: &Scene) -> Vec<Cup> {
        let z = scene.table_height();
        self.style
            .cups
            .iter()
            .enumerate()
            .map(|(i, uv)| {
                let w = scene.actor.to_world(&Vector3::new(uv[0], uv[1], z));
                let hue = (self.style.seed as f64 * 37.0 + i as f64 * 97.0) % 360.0;
                Cup {
                    base: [w.x, w.y, w.z],
                    radius: CUP.0,
                    height: CUP.1,
                    color: hsv(hue, 0.6, 0.8),
                }
            })
            .collect()
    }

    /// The colour of a drink's cup.
    pub fn drink_cup_color(&self) -> [u8; 3] {
        hsv((self.style.seed as f64 * 53.0) % 360.0, 0.5, 0.9)
    }

    /// Frame `k` of the video whose world poses are `poses` (`poses[k]` is shown; `cups` are in
    /// the scene during it). A dropped frame shows the previous frame's content: call it with
    /// that frame's cups, [`StyledVideo::source`] says which.
    ///
    /// # Errors
    /// [`Error::Config`] naming the frame if it cannot be rendered or compressed.
    pub fn frame(
        &self,
        cache: &mut SynthCache,
        poses: &[[f64; 9]],
        k: usize,
        cups: &[Cup],
    ) -> Result<RgbImage> {
        let j = self.source(k);
        let pose = poses
            .get(j)
            .ok_or_else(|| Error::Config(format!("synth: frame {k}: no pose")))?;
        // The exposure, half a frame interval long: `blur` poses evenly over the second half
        // of the way from the previous frame's pose to this one's.
        let prev = if j > 0 { &poses[j - 1] } else { pose };
        let n = self.style.blur.max(1);
        let exposure: Vec<[f64; 9]> = (1..=n)
            .map(|i| {
                let s = 0.5 + 0.5 * i as f64 / n as f64;
                std::array::from_fn(|c| prev[c] + s * (pose[c] - prev[c]))
            })
            .collect();
        let img = self
            .synth
            .render_exposure(
                cache,
                &self.camera,
                &exposure,
                cups,
                self.style.seed,
                j as u64,
            )
            .map_err(|e| Error::Config(format!("synth: frame {k}: {e}")))?;
        let rgb = RgbImage::from_raw(img.width, img.height, img.data)
            .ok_or_else(|| Error::Config(format!("synth: frame {k}: bad image buffer")))?;
        match self.style.jpeg_quality {
            Some(q) => jpeg_roundtrip(&rgb, q)
                .map_err(|e| Error::Config(format!("synth: frame {k}: JPEG: {e}"))),
            None => Ok(rgb),
        }
    }

    /// The frame whose content frame `k` shows: `k`, or the last frame before it that was not
    /// dropped.
    pub fn source(&self, k: usize) -> usize {
        let mut j = k;
        while j > 0 && self.style.dropped(j) {
            j -= 1;
        }
        j
    }
}

/// Compresses and decompresses a frame as a JPEG of `quality`.
fn jpeg_roundtrip(img: &RgbImage, quality: u8) -> std::result::Result<RgbImage, image::ImageError> {
    let mut buf = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, quality).encode_image(img)?;
    Ok(image::load_from_memory_with_format(&buf, image::ImageFormat::Jpeg)?.to_rgb8())
}

/// The cups of every frame of a video: the style's cups on the table and, for every run of
/// frames whose truth action contains `drink`, the drink's cup carried by the hand.
pub fn video_cups(
    video: &StyledVideo,
    scene: &Scene,
    poses_world: &[[f64; 9]],
    actions: &[(String, [f64; 2])],
) -> Vec<Vec<Cup>> {
    let table = video.table_cups(scene);
    let mut out = vec![table; poses_world.len()];
    if !video.style.drink_cup {
        return out;
    }
    let mut k = 0;
    while k < actions.len().min(poses_world.len()) {
        let (name, theta) = &actions[k];
        let mut e = k;
        while e < actions.len()
            && actions[e].0 == *name
            && actions[e]
                .1
                .iter()
                .zip(theta)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        {
            e += 1;
        }
        if name.contains("drink") && theta.iter().all(|v| v.is_finite()) {
            let tw = scene.theta_to_world(*theta);
            let cups = carried_cup(&poses_world[k..e], tw, video.drink_cup_color());
            for (o, c) in out[k..e].iter_mut().zip(cups) {
                o.push(c);
            }
        }
        k = e.max(k + 1);
    }
    out
}

/// Renders the frames of a synthetic sequence's `truth` (world poses, actions and θ per
/// frame) in `style` through the first camera of `scene` (the style's scene,
/// [`Style::scene`]), in parallel.
///
/// # Errors
/// As [`StyledVideo::frame`].
pub fn render_styled(
    style: &Style,
    scene: &Scene,
    truth: &crate::track_csv::Trajectory,
    lengths: [f64; 2],
) -> Result<Vec<RgbImage>> {
    use rayon::prelude::*;
    let video = StyledVideo::new(style, scene, lengths)?;
    let poses: Vec<[f64; 9]> = truth.rows.iter().map(|r| r.pose).collect();
    let actions: Vec<(String, [f64; 2])> = truth
        .rows
        .iter()
        .map(|r| (r.action.clone(), r.theta))
        .collect();
    let cups = video_cups(&video, scene, &poses, &actions);
    (0..poses.len())
        .into_par_iter()
        .map_init(SynthCache::default, |cache, k| {
            video.frame(cache, &poses, k, &cups[video.source(k)])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::default_scene;

    #[test]
    fn random_styles_are_reproducible_valid_and_varied() {
        let a: Vec<Style> = (0..40).map(Style::random).collect();
        assert_eq!(a, (0..40).map(Style::random).collect::<Vec<_>>());
        for s in &a {
            s.check().unwrap();
            let back = Style::parse(&s.to_toml(), std::path::Path::new("style.toml")).unwrap();
            assert_eq!(&back, s);
        }
        let sizes: std::collections::BTreeSet<_> = a.iter().map(|s| s.camera.width).collect();
        assert!(sizes.len() >= 4, "{sizes:?}");
        assert!(a.iter().any(|s| s.camera.azimuth_deg < -60.0));
        assert!(a.iter().any(|s| s.camera.azimuth_deg > 60.0));
        assert!(a.iter().any(|s| s.camera.azimuth_deg.abs() < 30.0));
        assert!(a.iter().any(|s| s.jpeg_quality.is_some()) && a.iter().any(|s| s.blur > 1));
        assert!(a.iter().any(|s| s.appearance.background.is_some()));
    }

    #[test]
    fn the_camera_sees_the_workspace_from_every_random_style() {
        let base = default_scene(320, 240);
        for seed in 0..40 {
            let s = Style::random(seed);
            let scene = s.scene(&base).unwrap();
            let cam = &scene.cameras[0];
            // The shoulder and the table region's corners are in the image.
            let mut pts = vec![scene.actor.origin];
            pts.extend(scene.table.corners());
            for p in pts {
                let (u, v) = cam.project(&p).expect("in front of the camera");
                assert!(cam.in_image(u, v), "seed {seed}: {p:?} at ({u:.0}, {v:.0})");
            }
        }
    }

    #[test]
    fn dropped_frames_repeat_the_previous_frame_and_blur_spreads_the_arm() {
        let base = default_scene(160, 120);
        let mut style = Style::random(3);
        style.camera.width = 160;
        style.camera.height = 120;
        style.drop_rate = 0.5;
        style.jpeg_quality = None;
        style.noise_sigma = 0.0;
        style.appearance.sway = 0.0;
        let scene = style.scene(&base).unwrap();
        let video = StyledVideo::new(&style, &scene, [0.29, 0.45]).unwrap();
        let rest = [0.0, 0.0, 1.0, 0.05, 0.1, 0.72, 0.1, 0.4, 0.68];
        let poses: Vec<[f64; 9]> = (0..12)
            .map(|k| {
                let s = f64::from(k) * 0.02;
                std::array::from_fn(|c| rest[c] + if c >= 3 && c % 3 == 0 { s } else { 0.0 })
            })
            .collect();
        let mut cache = SynthCache::default();
        let frames: Vec<RgbImage> = (0..12)
            .map(|k| video.frame(&mut cache, &poses, k, &[]).unwrap())
            .collect();
        let dropped: Vec<usize> = (1..12).filter(|&k| style.dropped(k)).collect();
        assert!(!dropped.is_empty() && dropped.len() < 11, "{dropped:?}");
        for k in 1..12 {
            assert_eq!(frames[k] == frames[k - 1], style.dropped(k), "frame {k}");
        }
        let mut sharp = style.clone();
        sharp.blur = 1;
        style.blur = 3;
        let (a, b) = (
            StyledVideo::new(&sharp, &scene, [0.29, 0.45]).unwrap(),
            StyledVideo::new(&style, &scene, [0.29, 0.45]).unwrap(),
        );
        let k = (1..12).find(|&k| !style.dropped(k)).unwrap();
        let (fa, fb) = (
            a.frame(&mut cache, &poses, k, &[]).unwrap(),
            b.frame(&mut cache, &poses, k, &[]).unwrap(),
        );
        assert!(fa != fb, "blur changes the frame");
    }

    #[test]
    fn the_drink_cup_stands_then_travels_with_the_hand() {
        let theta = Vector3::new(0.1, 0.4, 0.7);
        // The fingertip goes to the target, up by 30 cm, back, and home.
        let mut poses = Vec::new();
        let path = [
            [0.3, 0.1, 0.72],
            [0.1, 0.4, 0.7],
            [0.1, 0.3, 1.0],
            [0.1, 0.4, 0.7],
            [0.3, 0.1, 0.72],
        ];
        for w in path.windows(2) {
            for i in 0..10 {
                let s = f64::from(i) / 10.0;
                let t: [f64; 3] = std::array::from_fn(|c| w[0][c] + s * (w[1][c] - w[0][c]));
                poses.push([
                    0.0,
                    0.0,
                    1.0,
                    t[0],
                    t[1] - 0.2,
                    t[2] + 0.05,
                    t[0],
                    t[1],
                    t[2],
                ]);
            }
        }
        let cups = carried_cup(&poses, theta, [200, 0, 0]);
        assert_eq!(cups.len(), poses.len());
        let (a, b) = (cups[0].base, cups[poses.len() - 1].base);
        assert!(
            (0..3).all(|c| (a[c] - b[c]).abs() < 1e-12),
            "back where it stood"
        );
        let top = cups.iter().map(|c| c.base[2]).fold(f64::MIN, f64::max);
        assert!(top > 0.9, "lifted to {top}");
        assert!(cups.iter().all(|c| c.base[2] >= 0.7 - 1e-12));
    }
}
