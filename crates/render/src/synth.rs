//! Scene synthesis: renders an RGB frame of a given world-frame arm pose for synthetic
//! experiments (SPEC §7 test 14): a textured, cluttered background, the table, a torso and a
//! head, the arm with simple shading (the same geometry as the observation model) and sensor
//! noise. The seed is the only source of randomness: the same inputs give the same bytes.

use nalgebra::{Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};
use tiny_skia::{
    Color, FillRule, GradientStop, LinearGradient, Paint, PathBuilder, Pixmap, Point,
    PremultipliedColorU8, RadialGradient, Rect, SpreadMode, Stroke, Transform,
};

use crate::{
    ArmGeometry, Camera, ImageRgb8, Part2, RenderError,
    contour::{part_polygon, project_parts},
};

/// The physical table: a slab whose top is centred at `center` (world, metres; z = table
/// height), with half-extents along its own axes, turned by `yaw` about z.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table {
    /// Centre of the table top.
    pub center: [f64; 3],
    /// Half-extents of the top along the table's x and y axes.
    pub half_extents: [f64; 2],
    /// Rotation of the table axes about world z, radians.
    pub yaw: f64,
    /// Slab thickness.
    pub thickness: f64,
}

/// Torso (a vertical capsule) and head (a sphere) of the actor, world frame, metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Body {
    /// Bottom of the torso axis.
    pub torso_bottom: [f64; 3],
    /// Top of the torso axis.
    pub torso_top: [f64; 3],
    /// Torso radius.
    pub torso_radius: f64,
    /// Head centre.
    pub head_center: [f64; 3],
    /// Head radius.
    pub head_radius: f64,
    /// The other (not tracked) arm resting on the table: shoulder, elbow and fingertip, drawn
    /// when [`Appearance::other_arm`].
    #[serde(default)]
    pub other_arm: Option<[f64; 9]>,
}

impl Body {
    /// A torso and head placed beside the acting shoulder: `facing` is the direction the actor
    /// faces in the xy plane (the actor frame's y axis), `right_arm` whether the tracked arm is
    /// the right one.
    pub fn for_shoulder(shoulder: [f64; 3], facing: [f64; 2], right_arm: bool) -> Self {
        let f = Vector2::from(facing)
            .try_normalize(1e-12)
            .unwrap_or_else(Vector2::y);
        // Actor x = y × z = (f.y, −f.x): the actor's right.
        let right = Vector3::new(f.y, -f.x, 0.0);
        let s = Vector3::from(shoulder);
        let mid =
            s + right * if right_arm { -0.19 } else { 0.19 } - Vector3::new(f.x, f.y, 0.0) * 0.04;
        Self {
            torso_bottom: (mid - Vector3::new(0.0, 0.0, 0.45)).into(),
            torso_top: (mid - Vector3::new(0.0, 0.0, 0.08)).into(),
            torso_radius: 0.15,
            head_center: (mid + Vector3::new(0.0, 0.0, 0.2)).into(),
            head_radius: 0.1,
            other_arm: Some(resting_arm(
                2.0 * mid - s + Vector3::new(f.x, f.y, 0.0) * 0.08,
                Vector3::new(f.x, f.y, 0.0),
                (mid - s).normalize() * -1.0,
            )),
        }
    }
}

/// A resting arm from `shoulder`: the upper arm hangs down and a little forward, the forearm
/// lies forward and a little towards the body's midline (`inward`, horizontal).
fn resting_arm(shoulder: Vector3<f64>, forward: Vector3<f64>, inward: Vector3<f64>) -> [f64; 9] {
    let elbow = shoulder + Vector3::new(0.0, 0.0, -0.27) + forward * 0.06;
    let finger = elbow + forward * 0.42 + inward * 0.1 + Vector3::new(0.0, 0.0, 0.02);
    [
        shoulder.x, shoulder.y, shoulder.z, elbow.x, elbow.y, elbow.z, finger.x, finger.y, finger.z,
    ]
}

/// Renders synthetic frames. All fields are public; [`SceneSynth::new`] gives plausible
/// defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneSynth {
    /// The arm geometry (use the same as the likelihood model).
    pub geometry: ArmGeometry,
    /// The table, if any.
    pub table: Option<Table>,
    /// Torso and head, if any.
    pub body: Option<Body>,
    /// Number of clutter shapes in the background.
    pub clutter: usize,
    /// Standard deviation of the additive Gaussian sensor noise, grey levels.
    pub noise_sigma: f64,
    /// Sleeve colour (upper arm and torso).
    pub shirt_color: [u8; 3],
    /// Skin colour (forearm, hand, head).
    pub skin_color: [u8; 3],
    /// Table colour.
    pub table_color: [u8; 3],
    /// Lighting, textures and what else moves in the scene ([`Appearance::default`]: the
    /// classic look).
    #[serde(default)]
    pub appearance: Appearance,
}

/// The pattern on the table top.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TablePattern {
    /// Faint wood grain along the table's x axis.
    #[default]
    Grain,
    /// A plain top.
    Plain,
    /// A chequered cloth of 8 × 6 cells.
    Checker,
}

/// How a scene looks beyond its geometry: what randomised styles vary. The default is the
/// classic look of [`SceneSynth::new`] (its frames are byte for byte those of a synthesiser
/// without these settings).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Appearance {
    /// Contrast of the shading across the arm, torso and objects: 1 is the classic lit
    /// cylinder, 0 a flat fill, above 1 harder light.
    pub shading: f64,
    /// Where the light comes from in the image (radians, 0 = from the right, π/2 = from
    /// below); `None`: the classic light, from the top left.
    pub light_angle: Option<f64>,
    /// The background's base colour; `None`: drawn from the seed.
    pub background: Option<[u8; 3]>,
    /// Amplitude of the background's fine texture, grey levels (classic 6).
    pub texture: f64,
    /// The table top's pattern.
    pub table_pattern: TablePattern,
    /// Amplitude of the torso's and head's sway, metres (0: still).
    pub sway: f64,
    /// Draws the other arm, resting on the table (needs [`Body::other_arm`]).
    pub other_arm: bool,
    /// Global brightness factor (exposure; 1 = as drawn).
    pub gain: f64,
    /// Darkening towards the corners: the brightness at the image's corner is `1 − vignette`.
    pub vignette: f64,
}

impl Default for Appearance {
    fn default() -> Self {
        Self {
            shading: 1.0,
            light_angle: None,
            background: None,
            texture: 6.0,
            table_pattern: TablePattern::Grain,
            sway: 0.0,
            other_arm: false,
            gain: 1.0,
            vignette: 0.0,
        }
    }
}

/// A cup (an upright cylinder) standing on the table or carried by the hand, world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Cup {
    /// Centre of its base, metres.
    pub base: [f64; 3],
    /// Radius, metres.
    pub radius: f64,
    /// Height, metres.
    pub height: f64,
    /// Colour.
    pub color: [u8; 3],
}

impl SceneSynth {
    /// Defaults: 40 clutter shapes, noise σ = 3 grey levels, a blue shirt, skin, a wooden table.
    pub fn new(geometry: ArmGeometry, table: Option<Table>, body: Option<Body>) -> Self {
        Self {
            geometry,
            table,
            body,
            clutter: 40,
            noise_sigma: 3.0,
            shirt_color: [40, 70, 150],
            skin_color: [225, 170, 140],
            table_color: [165, 120, 75],
            appearance: Appearance::default(),
        }
    }

    /// Renders the frame seen by `camera` of the arm `pose` (p, q, r, world, metres, as the
    /// observation model renders it). Deterministic in (`self`, `camera`, `pose`, `seed`).
    pub fn render(
        &self,
        camera: &Camera,
        pose: &[f64; 9],
        seed: u64,
    ) -> Result<ImageRgb8, RenderError> {
        self.render_cached(&mut SynthCache::default(), camera, pose, seed)
    }

    /// [`SceneSynth::render`] for a stream of frames: the parts that do not depend on the pose
    /// (background, clutter, table, and the noise field, which the seed fixes) are drawn once
    /// into `cache` and reused while `self`, `camera` and `seed` stay the same. The bytes are
    /// those of [`SceneSynth::render`]. The noise is the same in every frame; for video, whose
    /// noise changes from frame to frame, use [`SceneSynth::render_frame`].
    pub fn render_cached(
        &self,
        cache: &mut SynthCache,
        camera: &Camera,
        pose: &[f64; 9],
        seed: u64,
    ) -> Result<ImageRgb8, RenderError> {
        self.render_frame(cache, camera, pose, seed, 0)
    }

    /// Frame `frame` of a video: [`SceneSynth::render_cached`] with sensor noise that changes
    /// from frame to frame. The noise of frame `frame` is a window of the seed's noise field
    /// (drawn once, [`NOISE_MARGIN`] values longer than a frame) at an offset that a hash of
    /// (`seed`, `frame`) picks, so every pixel's noise is a different draw in every frame (up
    /// to the offsets' collisions) while the scene stays fixed. Frame 0 has offset 0: its bytes
    /// are those of [`SceneSynth::render`]. Deterministic in (`self`, `camera`, `pose`, `seed`,
    /// `frame`).
    pub fn render_frame(
        &self,
        cache: &mut SynthCache,
        camera: &Camera,
        pose: &[f64; 9],
        seed: u64,
        frame: u64,
    ) -> Result<ImageRgb8, RenderError> {
        self.render_exposure(cache, camera, std::slice::from_ref(pose), &[], seed, frame)
    }

    /// Frame `frame` of a video as [`SceneSynth::render_frame`] draws it, with `cups` in the
    /// scene and the arm moving during the exposure: the frame is the mean of the scene drawn
    /// at each pose of `exposure` (one pose: no motion blur; [`SceneSynth::render_frame`]'s
    /// bytes when `cups` is empty). Deterministic in all inputs.
    ///
    /// # Errors
    /// [`RenderError`] for an invalid camera or geometry, an empty `exposure` or a frame that
    /// cannot be allocated.
    pub fn render_exposure(
        &self,
        cache: &mut SynthCache,
        camera: &Camera,
        exposure: &[[f64; 9]],
        cups: &[Cup],
        seed: u64,
        frame: u64,
    ) -> Result<ImageRgb8, RenderError> {
        camera.validate()?;
        self.geometry.validate()?;
        if exposure.is_empty() {
            return Err(RenderError::InvalidImage(
                "synthesis needs at least one pose per frame".into(),
            ));
        }
        let (w, h) = (camera.width, camera.height);
        let fresh = cache
            .layer
            .as_ref()
            .is_none_or(|l| l.synth != *self || l.camera != *camera || l.seed != seed);
        if fresh {
            cache.layer = None;
            let mut pix = Pixmap::new(w, h).ok_or_else(|| {
                RenderError::InvalidImage(format!("cannot allocate a {w}×{h} frame"))
            })?;
            let mut rng = Pcg64Mcg::seed_from_u64(seed);
            background(&mut pix, &mut rng, &self.appearance);
            clutter(&mut pix, &mut rng, self.clutter);
            if let Some(t) = &self.table {
                self.draw_table(&mut pix, camera, t);
            }
            let noise = noise_field(
                pix.data().len() / 4 * 3 + NOISE_MARGIN,
                self.noise_sigma,
                &mut rng,
            );
            cache.layer = Some(Layer {
                synth: self.clone(),
                camera: camera.clone(),
                seed,
                pix,
                noise,
            });
        }
        let Some(layer) = cache.layer.as_ref() else {
            return Err(RenderError::InvalidImage("synthesis cache is empty".into()));
        };
        let noise = layer.noise.as_deref().map(|n| {
            let offset = noise_offset(seed, frame);
            &n[offset..]
        });
        if let [pose] = exposure {
            let mut pix = layer.pix.clone();
            self.draw_moving(&mut pix, camera, pose, cups, frame);
            return Ok(to_rgb(&pix, noise, &self.appearance));
        }
        // Motion blur: the mean of the exposure's frames.
        let mut sum = vec![0u32; layer.pix.data().len()];
        for pose in exposure {
            let mut pix = layer.pix.clone();
            self.draw_moving(&mut pix, camera, pose, cups, frame);
            for (s, v) in sum.iter_mut().zip(pix.data()) {
                *s += u32::from(*v);
            }
        }
        let n = exposure.len() as u32;
        let mut pix = layer.pix.clone();
        for (d, s) in pix.data_mut().iter_mut().zip(&sum) {
            *d = ((s + n / 2) / n) as u8;
        }
        Ok(to_rgb(&pix, noise, &self.appearance))
    }

    /// Draws what changes from frame to frame, far to near: torso, head and the other arm (with
    /// their sway), the cups and the tracked arm at `pose`.
    fn draw_moving(
        &self,
        pix: &mut Pixmap,
        camera: &Camera,
        pose: &[f64; 9],
        cups: &[Cup],
        frame: u64,
    ) {
        let look = &self.appearance;
        let mut items: Vec<(f64, Part2, [u8; 3], bool)> = Vec::new();
        if let Some(b) = &self.body {
            // The sway: slow, incommensurate sines in x and y, zero at the torso's bottom.
            let t = frame as f64;
            let sway = Vector3::new(
                look.sway * (t * 0.071).sin(),
                look.sway * 0.6 * (t * 0.043 + 1.0).sin(),
                0.0,
            );
            let bot = Vector3::from(b.torso_bottom);
            let top = Vector3::from(b.torso_top) + sway;
            let cone = [
                bot[0], bot[1], bot[2], top[0], top[1], top[2], top[0], top[1], top[2],
            ];
            let torso = ArmGeometry {
                upper_radii: [b.torso_radius; 2],
                forearm_radii: [0.0; 2],
                hand_half_axes: [0.0; 3],
                ..ArmGeometry::default()
            };
            let depth = camera.to_camera(&(0.5 * (bot + top))).z;
            if let Some(p) = project_parts(camera, &torso, &cone).first() {
                items.push((depth + b.torso_radius, *p, self.shirt_color, true));
            }
            let hc = Vector3::from(b.head_center) + sway * 1.3;
            let xc = camera.to_camera(&hc);
            if let Some(c) = camera.project_camera(&xc) {
                let r = b.head_radius * camera.mean_focal() / xc.z;
                let head = Part2::Capsule {
                    c0: [c.x, c.y],
                    c1: [c.x, c.y],
                    r0: r,
                    r1: r,
                };
                items.push((xc.z, head, self.skin_color, false));
                // Neck.
                let neck_top = hc - Vector3::new(0.0, 0.0, 0.5 * b.head_radius);
                let neck = [
                    top[0],
                    top[1],
                    top[2],
                    neck_top[0],
                    neck_top[1],
                    neck_top[2],
                    neck_top[0],
                    neck_top[1],
                    neck_top[2],
                ];
                let g = ArmGeometry {
                    upper_radii: [0.05; 2],
                    ..torso
                };
                if let Some(p) = project_parts(camera, &g, &neck).first() {
                    items.push((xc.z + 0.01, *p, self.skin_color, true));
                }
            }
            if look.other_arm
                && let Some(rest) = b.other_arm
            {
                let mut rest = rest;
                for (i, v) in rest.iter_mut().enumerate() {
                    *v += sway[i % 3] * [1.0, 0.6, 0.3][i / 3];
                }
                self.push_arm(&mut items, camera, &rest);
            }
        }
        for c in cups {
            let base = Vector3::from(c.base);
            let top = base + Vector3::new(0.0, 0.0, c.height);
            let (xb, xt) = (camera.to_camera(&base), camera.to_camera(&top));
            if let (Some(pb), Some(pt)) = (camera.project_camera(&xb), camera.project_camera(&xt)) {
                let f = camera.mean_focal();
                let cup = Part2::Capsule {
                    c0: [pb.x, pb.y],
                    c1: [pt.x, pt.y],
                    r0: c.radius * f / xb.z,
                    r1: c.radius * f / xt.z,
                };
                items.push((0.5 * (xb.z + xt.z), cup, c.color, true));
            }
        }
        self.push_arm(&mut items, camera, pose);
        items.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut poly = Vec::new();
        for (_, part, color, linear) in &items {
            draw_part(pix, part, *color, *linear, look, &mut poly);
        }
    }

    /// The three parts of an arm at `pose` (world) with their depths and colours.
    fn push_arm(
        &self,
        items: &mut Vec<(f64, Part2, [u8; 3], bool)>,
        camera: &Camera,
        pose: &[f64; 9],
    ) {
        let Some(parts) = self.geometry.parts(pose) else {
            return;
        };
        let projected = project_parts(camera, &self.geometry, pose);
        let depths = [
            camera.to_camera(&(0.5 * (parts.upper.0 + parts.upper.1))).z,
            camera
                .to_camera(&(0.5 * (parts.forearm.0 + parts.forearm.1)))
                .z,
            camera.to_camera(&parts.hand_centre).z,
        ];
        let colors = [
            self.shirt_color,
            self.skin_color,
            shade(self.skin_color, 0.95),
        ];
        // project_parts keeps the order upper, forearm, hand but may drop parts behind the
        // camera; match them by kind and order.
        let mut k = 0;
        for p in projected {
            let idx = match p {
                Part2::Ellipse { .. } => 2,
                Part2::Capsule { .. } => {
                    k += 1;
                    k - 1
                }
            };
            let idx = idx.min(2);
            items.push((depths[idx], p, colors[idx], true));
        }
    }

    fn draw_table(&self, pix: &mut Pixmap, camera: &Camera, t: &Table) {
        let c = Vector3::from(t.center);
        let (s, co) = t.yaw.sin_cos();
        let ex = Vector3::new(co, s, 0.0) * t.half_extents[0];
        let ey = Vector3::new(-s, co, 0.0) * t.half_extents[1];
        let down = Vector3::new(0.0, 0.0, -t.thickness.max(0.0));
        let top = [c - ex - ey, c + ex - ey, c + ex + ey, c - ex + ey];
        let mut all = Vec::with_capacity(8);
        for corner in top.iter().chain(top.map(|x| x + down).iter()) {
            match camera.project(corner) {
                Some(uv) if uv.x.abs() < 1e6 && uv.y.abs() < 1e6 => all.push([uv.x, uv.y]),
                _ => return, // a table corner behind the camera: leave the table out
            }
        }
        let slab = convex_hull(&all);
        let dark = shade(self.table_color, 0.55);
        fill_polygon(
            pix,
            &slab,
            &Paint {
                shader: solid(dark),
                ..Paint::default()
            },
        );
        let top2: Vec<[f64; 2]> = all[..4].to_vec();
        // Shade the top along its depth: lighter far away.
        let (near, far) = (top2[0], top2[3]);
        let stops = vec![
            GradientStop::new(0.0, color(shade(self.table_color, 0.9))),
            GradientStop::new(1.0, color(shade(self.table_color, 1.12))),
        ];
        let shader = LinearGradient::new(
            pt(near),
            pt(far),
            stops,
            SpreadMode::Pad,
            Transform::identity(),
        )
        .unwrap_or_else(|| solid(self.table_color));
        fill_polygon(
            pix,
            &top2,
            &Paint {
                shader,
                ..Paint::default()
            },
        );
        match self.appearance.table_pattern {
            TablePattern::Grain => self.draw_grain(pix, camera, c, ex, ey),
            TablePattern::Plain => {}
            TablePattern::Checker => {
                // Every other cell of an 8 × 6 grid, darker.
                let paint = Paint {
                    shader: solid(shade(self.table_color, 0.7)),
                    ..Paint::default()
                };
                let (nx, ny) = (8, 6);
                for i in 0..nx {
                    for j in (i % 2..ny).step_by(2) {
                        let at = |a: usize, b: usize| {
                            let (fa, fb) = (
                                a as f64 / nx as f64 * 2.0 - 1.0,
                                b as f64 / ny as f64 * 2.0 - 1.0,
                            );
                            camera.project(&(c + ex * fa + ey * fb)).map(|p| [p.x, p.y])
                        };
                        let quad = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                        if quad.iter().all(Option::is_some) {
                            let quad: Vec<[f64; 2]> = quad.into_iter().flatten().collect();
                            fill_polygon(pix, &quad, &paint);
                        }
                    }
                }
            }
        }
    }

    /// Wood grain: a few faint lines along the table's x axis.
    fn draw_grain(
        &self,
        pix: &mut Pixmap,
        camera: &Camera,
        c: Vector3<f64>,
        ex: Vector3<f64>,
        ey: Vector3<f64>,
    ) {
        let grain = shade(self.table_color, 0.8);
        let paint = Paint {
            shader: solid(grain),
            ..Paint::default()
        };
        for k in 1..8 {
            let f = f64::from(k) / 8.0 * 2.0 - 1.0;
            let a = camera.project(&(c - ex + ey * f));
            let b = camera.project(&(c + ex + ey * f));
            if let (Some(a), Some(b)) = (a, b) {
                let mut pb = PathBuilder::new();
                pb.move_to(a.x as f32 + 0.5, a.y as f32 + 0.5);
                pb.line_to(b.x as f32 + 0.5, b.y as f32 + 0.5);
                if let Some(path) = pb.finish() {
                    let stroke = Stroke {
                        width: 1.0,
                        ..Stroke::default()
                    };
                    pix.stroke_path(&path, &paint, &stroke, Transform::identity(), None);
                }
            }
        }
    }
}

fn color(c: [u8; 3]) -> Color {
    Color::from_rgba8(c[0], c[1], c[2], 255)
}

fn solid(c: [u8; 3]) -> tiny_skia::Shader<'static> {
    tiny_skia::Shader::SolidColor(color(c))
}

fn shade(c: [u8; 3], f: f64) -> [u8; 3] {
    c.map(|v| (f64::from(v) * f).round().clamp(0.0, 255.0) as u8)
}

fn pt(p: [f64; 2]) -> Point {
    Point::from_xy(p[0] as f32 + 0.5, p[1] as f32 + 0.5)
}

fn fill_polygon(pix: &mut Pixmap, poly: &[[f64; 2]], paint: &Paint<'_>) {
    let mut pb = PathBuilder::new();
    for (i, p) in poly.iter().enumerate() {
        let (x, y) = (p[0] as f32 + 0.5, p[1] as f32 + 0.5);
        if i == 0 {
            pb.move_to(x, y);
        } else {
            pb.line_to(x, y);
        }
    }
    pb.close();
    if let Some(path) = pb.finish() {
        pix.fill_path(&path, paint, FillRule::Winding, Transform::identity(), None);
    }
}

/// Andrew's monotone chain.
fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        for &x in &p {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], x) <= 0.0
            {
                hull.pop();
            }
            hull.push(x);
        }
        hull.pop();
        if pass == 0 {
            p.reverse();
        }
    }
    hull
}

/// A shaded part: capsules get a gradient across their axis (a lit cylinder), ellipses and
/// discs a radial highlight.
fn draw_part(
    pix: &mut Pixmap,
    part: &Part2,
    base: [u8; 3],
    linear: bool,
    look: &Appearance,
    poly: &mut Vec<[f64; 2]>,
) {
    poly.clear();
    part_polygon(part, poly);
    if poly.len() < 3 {
        return;
    }
    let stops = |lo: f64, mid: f64, hi: f64| {
        vec![
            GradientStop::new(0.0, color(shade(base, lo))),
            GradientStop::new(mid as f32, color(shade(base, hi))),
            GradientStop::new(1.0, color(shade(base, lo * 0.9))),
        ]
    };
    // Shading contrast: the classic stops scaled about 1.
    let k = |v: f64| 1.0 + look.shading * (v - 1.0);
    let light = look.light_angle.map(|a| Vector2::new(a.cos(), a.sin()));
    let shader = match *part {
        Part2::Capsule { c0, c1, r0, r1 } if linear && (r0 + r1) > 0.5 => {
            let d = Vector2::from(c1) - Vector2::from(c0);
            let mut n = Vector2::new(-d.y, d.x)
                .try_normalize(1e-9)
                .unwrap_or_else(Vector2::x);
            // The highlight lies towards the light: at 0.45 of the way from a to b classically.
            let mut mid = 0.45;
            if let Some(l) = light {
                if n.dot(&l) > 0.0 {
                    n = -n;
                }
                mid = 0.5 + 0.4 * n.dot(&l).abs();
            }
            let r = 0.5 * (r0 + r1);
            let m = 0.5 * (Vector2::from(c0) + Vector2::from(c1));
            let (a, b) = (m - n * r, m + n * r);
            LinearGradient::new(
                pt([a.x, a.y]),
                pt([b.x, b.y]),
                stops(k(0.6), mid, k(1.15)),
                SpreadMode::Pad,
                Transform::identity(),
            )
        }
        Part2::Capsule { c0, r0, .. } if r0 > 0.5 => {
            let off = light.map_or([-0.3 * r0, -0.3 * r0], |l| {
                [-0.4 * r0 * l.x, -0.4 * r0 * l.y]
            });
            RadialGradient::new(
                pt([c0[0] + off[0], c0[1] + off[1]]),
                pt(c0),
                (1.3 * r0) as f32,
                stops(k(1.15), 0.45, k(0.95)),
                SpreadMode::Pad,
                Transform::identity(),
            )
        }
        Part2::Ellipse { c, a, .. } if a > 0.5 => {
            let off = light.map_or([0.0, -0.2 * a], |l| [-0.3 * a * l.x, -0.3 * a * l.y]);
            RadialGradient::new(
                pt([c[0] + off[0], c[1] + off[1]]),
                pt(c),
                (1.2 * a) as f32,
                stops(k(1.1), 0.45, k(0.85)),
                SpreadMode::Pad,
                Transform::identity(),
            )
        }
        _ => None,
    }
    .unwrap_or_else(|| solid(base));
    fill_polygon(
        pix,
        poly,
        &Paint {
            shader,
            ..Paint::default()
        },
    );
}

/// A wall-like background: a random base colour, low-frequency shading and fine texture.
fn background(pix: &mut Pixmap, rng: &mut Pcg64Mcg, look: &Appearance) {
    let (w, h) = (pix.width() as usize, pix.height() as usize);
    let mut base = [
        rng.random_range(90.0..190.0),
        rng.random_range(90.0..190.0),
        rng.random_range(90.0..190.0),
    ];
    if let Some(b) = look.background {
        base = b.map(f64::from);
    }
    let wave = |len: usize, rng: &mut Pcg64Mcg| -> Vec<f64> {
        let comps: Vec<(f64, f64, f64)> = (0..3)
            .map(|_| {
                (
                    rng.random_range(0.002..0.05),
                    rng.random_range(0.0..6.3),
                    rng.random_range(4.0..18.0),
                )
            })
            .collect();
        (0..len)
            .map(|i| {
                comps
                    .iter()
                    .map(|&(f, ph, a)| a * (f * i as f64 + ph).sin())
                    .sum()
            })
            .collect()
    };
    let cols = wave(w, rng);
    let rows = wave(h, rng);
    let texture: Vec<f64> = (0..251)
        .map(|_| rng.random_range(-6.0..6.0) * (look.texture / 6.0))
        .collect();
    let px = pix.pixels_mut();
    for y in 0..h {
        for x in 0..w {
            let t = rows[y] + cols[x] + texture[(x * 31 + y * 17 + (x * y) % 7) % texture.len()];
            let c = base.map(|b| (b + t).clamp(0.0, 255.0) as u8);
            if let Some(p) = PremultipliedColorU8::from_rgba(c[0], c[1], c[2], 255) {
                px[y * w + x] = p;
            }
        }
    }
}

/// Random rectangles, discs, ellipses and strokes (posters, shelves, objects).
fn clutter(pix: &mut Pixmap, rng: &mut Pcg64Mcg, n: usize) {
    let (w, h) = (f64::from(pix.width()), f64::from(pix.height()));
    let scale = w.min(h);
    for _ in 0..n {
        let c = [
            rng.random_range(0..=255u8),
            rng.random_range(0..=255u8),
            rng.random_range(0..=255u8),
        ];
        let paint = Paint {
            shader: solid(c),
            ..Paint::default()
        };
        let (x, y) = (
            rng.random_range(-0.1..1.1) * w,
            rng.random_range(-0.1..1.1) * h,
        );
        let size = rng.random_range(0.03..0.25) * scale;
        let angle = rng.random_range(-0.5..0.5f64);
        let ts = Transform::from_rotate_at(angle.to_degrees() as f32, x as f32, y as f32);
        match rng.random_range(0..4u8) {
            0 => {
                let aspect = rng.random_range(0.3..3.0);
                if let Some(r) =
                    Rect::from_xywh(x as f32, y as f32, size as f32, (size * aspect) as f32)
                {
                    pix.fill_rect(r, &paint, ts, None);
                }
            }
            1 => {
                if let Some(path) =
                    PathBuilder::from_circle(x as f32, y as f32, (size * 0.5) as f32)
                {
                    pix.fill_path(
                        &path,
                        &paint,
                        FillRule::Winding,
                        Transform::identity(),
                        None,
                    );
                }
            }
            2 => {
                let aspect = rng.random_range(0.3..1.0);
                if let Some(r) =
                    Rect::from_xywh(x as f32, y as f32, size as f32, (size * aspect) as f32)
                    && let Some(path) = PathBuilder::from_oval(r)
                {
                    pix.fill_path(&path, &paint, FillRule::Winding, ts, None);
                }
            }
            _ => {
                let mut pb = PathBuilder::new();
                pb.move_to(x as f32, y as f32);
                pb.line_to(
                    (x + size * 1.5) as f32,
                    (y + size * rng.random_range(-0.5..0.5)) as f32,
                );
                if let Some(path) = pb.finish() {
                    let stroke = Stroke {
                        width: rng.random_range(1.0..6.0),
                        ..Stroke::default()
                    };
                    pix.stroke_path(&path, &paint, &stroke, Transform::identity(), None);
                }
            }
        }
    }
}

/// The additive Gaussian sensor noise of one frame, `len` values (R, G, B per pixel, row-major);
/// `None` without noise (σ ≤ 0 or not finite).
fn noise_field(len: usize, sigma: f64, rng: &mut Pcg64Mcg) -> Option<Vec<f64>> {
    let d = Normal::new(0.0, sigma).ok().filter(|_| sigma > 0.0)?;
    Some((0..len).map(|_| d.sample(rng)).collect())
}

/// How many noise values the noise field holds beyond one frame's: the range of
/// [`SceneSynth::render_frame`]'s per-frame offsets.
pub const NOISE_MARGIN: usize = 3 << 16;

/// The offset into the noise field of frame `frame` (0 for frame 0): a multiple of 3 (R, G, B
/// stay aligned) below [`NOISE_MARGIN`], from a SplitMix64 hash of (`seed`, `frame`).
fn noise_offset(seed: u64, frame: u64) -> usize {
    if frame == 0 {
        return 0;
    }
    let mut z = seed ^ frame.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    3 * (z % (NOISE_MARGIN as u64 / 3)) as usize
}

/// The pose-independent part of a frame ([`SceneSynth::render_cached`]).
#[derive(Debug, Clone)]
struct Layer {
    synth: SceneSynth,
    camera: Camera,
    seed: u64,
    /// Background, clutter and table.
    pix: Pixmap,
    /// The sensor noise, per channel value.
    noise: Option<Vec<f64>>,
}

/// What [`SceneSynth::render_cached`] keeps between frames (one per view).
#[derive(Debug, Clone, Default)]
pub struct SynthCache {
    layer: Option<Layer>,
}

/// Pixmap → RGB8 with the appearance's gain and vignette and additive sensor noise (one value
/// per channel value).
fn to_rgb(pix: &Pixmap, noise: Option<&[f64]>, look: &Appearance) -> ImageRgb8 {
    let (w, h) = (pix.width() as usize, pix.height() as usize);
    let mut img = ImageRgb8::new(pix.width(), pix.height());
    // Exact comparisons: the classic look (gain 1, no vignette) keeps its bytes.
    let lit = (look.gain - 1.0).abs() > 0.0 || look.vignette.abs() > 0.0;
    let (cx, cy) = (0.5 * (w as f64 - 1.0), 0.5 * (h as f64 - 1.0));
    let r2max = (cx * cx + cy * cy).max(1.0);
    for (i, (o, p)) in img.data.chunks_exact_mut(3).zip(pix.pixels()).enumerate() {
        let c = p.demultiply();
        let rgb = [c.red(), c.green(), c.blue()];
        let light = if lit {
            let (x, y) = ((i % w) as f64 - cx, (i / w) as f64 - cy);
            look.gain * (1.0 - look.vignette * (x * x + y * y) / r2max)
        } else {
            1.0
        };
        for (k, (dst, v)) in o.iter_mut().zip(rgb).enumerate() {
            let n = noise.map_or(0.0, |n| n[3 * i + k]);
            let v = if lit {
                f64::from(v) * light
            } else {
                f64::from(v)
            };
            *dst = (v + n).round().clamp(0.0, 255.0) as u8;
        }
    }
    img
}
