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
        }
    }
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
        camera.validate()?;
        self.geometry.validate()?;
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
            background(&mut pix, &mut rng);
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
        let mut pix = layer.pix.clone();
        // Body parts and arm parts, far to near.
        let mut items: Vec<(f64, Part2, [u8; 3], bool)> = Vec::new();
        if let Some(b) = &self.body {
            let (bot, top) = (Vector3::from(b.torso_bottom), Vector3::from(b.torso_top));
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
            let hc = Vector3::from(b.head_center);
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
        }
        if let Some(parts) = self.geometry.parts(pose) {
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
        items.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut poly = Vec::new();
        for (_, part, color, linear) in &items {
            draw_part(&mut pix, part, *color, *linear, &mut poly);
        }
        let noise = layer.noise.as_deref().map(|n| {
            let offset = noise_offset(seed, frame);
            &n[offset..]
        });
        Ok(to_rgb(&pix, noise))
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
        // Wood grain: a few faint lines along the table's x axis.
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
    poly: &mut Vec<[f64; 2]>,
) {
    poly.clear();
    part_polygon(part, poly);
    if poly.len() < 3 {
        return;
    }
    let stops = |lo: f64, hi: f64| {
        vec![
            GradientStop::new(0.0, color(shade(base, lo))),
            GradientStop::new(0.45, color(shade(base, hi))),
            GradientStop::new(1.0, color(shade(base, lo * 0.9))),
        ]
    };
    let shader = match *part {
        Part2::Capsule { c0, c1, r0, r1 } if linear && (r0 + r1) > 0.5 => {
            let d = Vector2::from(c1) - Vector2::from(c0);
            let n = Vector2::new(-d.y, d.x)
                .try_normalize(1e-9)
                .unwrap_or_else(Vector2::x);
            let r = 0.5 * (r0 + r1);
            let m = 0.5 * (Vector2::from(c0) + Vector2::from(c1));
            let (a, b) = (m - n * r, m + n * r);
            LinearGradient::new(
                pt([a.x, a.y]),
                pt([b.x, b.y]),
                stops(0.6, 1.15),
                SpreadMode::Pad,
                Transform::identity(),
            )
        }
        Part2::Capsule { c0, r0, .. } if r0 > 0.5 => RadialGradient::new(
            pt([c0[0] - 0.3 * r0, c0[1] - 0.3 * r0]),
            pt(c0),
            (1.3 * r0) as f32,
            stops(1.15, 0.95),
            SpreadMode::Pad,
            Transform::identity(),
        ),
        Part2::Ellipse { c, a, .. } if a > 0.5 => RadialGradient::new(
            pt([c[0], c[1] - 0.2 * a]),
            pt(c),
            (1.2 * a) as f32,
            stops(1.1, 0.85),
            SpreadMode::Pad,
            Transform::identity(),
        ),
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
fn background(pix: &mut Pixmap, rng: &mut Pcg64Mcg) {
    let (w, h) = (pix.width() as usize, pix.height() as usize);
    let base = [
        rng.random_range(90.0..190.0),
        rng.random_range(90.0..190.0),
        rng.random_range(90.0..190.0),
    ];
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
    let texture: Vec<f64> = (0..251).map(|_| rng.random_range(-6.0..6.0)).collect();
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

/// Pixmap → RGB8 with additive sensor noise (one value per channel value).
fn to_rgb(pix: &Pixmap, noise: Option<&[f64]>) -> ImageRgb8 {
    let mut img = ImageRgb8::new(pix.width(), pix.height());
    for (i, (o, p)) in img.data.chunks_exact_mut(3).zip(pix.pixels()).enumerate() {
        let c = p.demultiply();
        let rgb = [c.red(), c.green(), c.blue()];
        for (k, (dst, v)) in o.iter_mut().zip(rgb).enumerate() {
            let n = noise.map_or(0.0, |n| n[3 * i + k]);
            *dst = (f64::from(v) + n).round().clamp(0.0, 255.0) as u8;
        }
    }
    img
}
