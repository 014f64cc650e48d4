//! The MCAP track of DESIGN.md, JSON-encoded with Foxglove schemas, zstd chunks, indexed.
//!
//! Topics (every message has a non-empty frame id; log time = frame time):
//! * `/tf` — `foxglove.FrameTransforms`: world → table, world → actor, world → each camera
//!   (the camera's optical frame: x right, y down, z forward), repeated every frame.
//! * `/actrack/arm` — `foxglove.SceneUpdate`: entities `best` (the best particle's pose) and
//!   `smoothed` (its median-filtered pose), joints as spheres and segments as cylinders, plus
//!   the `table` region as a thin cube; frame `world`.
//! * `/actrack/particles` — `foxglove.SceneUpdate`: the θ cloud on the table as small spheres
//!   coloured by action (duplicates after resampling merged); frame `world`.
//! * `/actrack/estimate` — `actrack.Estimate` (JSON schema): action posterior, θ mean/std in
//!   the actor frame and on the table in the world, entropies, ESS, progress.
//! * optional `/camera/image` (`foxglove.CompressedImage`, PNG), `/camera/calibration`
//!   (`foxglove.CameraCalibration`) and `/actrack/contour` (`foxglove.ImageAnnotations`: the
//!   best pose's contour and the θ dot), for the first camera.
//!
//! The file is written under a temporary name and renamed by [`TrackWriter::finish`].

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use serde::Serialize;
use serde_json::{Value, json};

use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::track_csv::temp_path;

/// Colours per action (RGBA 0–1), cycled.
pub const ACTION_COLOURS: [[f64; 3]; 6] = [
    [0.90, 0.30, 0.20],
    [0.20, 0.60, 0.90],
    [0.30, 0.80, 0.30],
    [0.90, 0.70, 0.10],
    [0.70, 0.30, 0.80],
    [0.40, 0.40, 0.40],
];

/// The per-frame estimate message (`/actrack/estimate`).
#[derive(Clone, Debug, Serialize)]
pub struct EstimateMsg {
    /// Always `actor`.
    pub frame_id: String,
    /// Frame index.
    pub frame: usize,
    /// Frame time, seconds.
    pub time: f64,
    /// Action names.
    pub actions: Vec<String>,
    /// P(a | I_1:t), same order.
    pub action_posterior: Vec<f64>,
    /// argmax of the posterior.
    pub map_action: String,
    /// Mean θ (actor frame, metres).
    pub theta_mean: [f64; 2],
    /// Per-component std of θ (metres).
    pub theta_std: [f64; 2],
    /// θ̄ on the table, world coordinates.
    pub theta_world: [f64; 3],
    /// Histogram entropy of θ in [0, 1].
    pub theta_entropy: f64,
    /// Action entropy (nats).
    pub action_entropy: f64,
    /// Effective sample size.
    pub ess: f64,
    /// Mean HMM state k (1-based) over particles.
    pub k: f64,
    /// Mean progress k/N in [0, 1].
    pub progress: f64,
}

/// What is written for one frame.
pub struct FrameRecord<'a> {
    /// Frame index.
    pub frame: usize,
    /// Frame time, seconds.
    pub time: f64,
    /// Best particle's pose (world).
    pub best_pose: [f64; 9],
    /// Median-filtered pose (world).
    pub smoothed_pose: [f64; 9],
    /// Particles: (action index, θ on the table in world coordinates).
    pub particles: &'a [(usize, [f64; 3])],
    /// The estimate.
    pub estimate: &'a EstimateMsg,
    /// PNG bytes of the first camera's frame, if images are written.
    pub png: Option<&'a [u8]>,
    /// Contour points of the best pose in the first camera (pixels), with images.
    pub contour: Option<&'a [[f64; 2]]>,
    /// θ̄ projected into the first camera and its display colour (RGB 0–1), with images.
    pub theta_dot: Option<([f64; 2], [f64; 3])>,
}

struct Channels {
    tf: u16,
    arm: u16,
    particles: u16,
    estimate: u16,
    image: u16,
    calibration: u16,
    contour: u16,
}

/// Writes a track MCAP.
pub struct TrackWriter {
    w: mcap::Writer<BufWriter<File>>,
    ch: Channels,
    tmp: PathBuf,
    path: PathBuf,
    scene: Scene,
    seq: u32,
    images: bool,
    frames: usize,
    /// Declared after `w`: the writer is closed before the unfinished file is removed.
    guard: crate::track_csv::TempGuard,
}

fn mcap_err(path: &Path, e: &mcap::McapError) -> Error {
    Error::write(path, std::io::Error::other(e.to_string()))
}

fn time(t: f64) -> Value {
    let ns = (t.max(0.0) * 1e9).round() as u64;
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn quat(r: &nalgebra::Matrix3<f64>) -> Value {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    json!({"x": q.i, "y": q.j, "z": q.k, "w": q.w})
}

fn vec3(v: &Vector3<f64>) -> Value {
    json!({"x": v.x, "y": v.y, "z": v.z})
}

fn colour(c: [f64; 3], a: f64) -> Value {
    json!({"r": c[0], "g": c[1], "b": c[2], "a": a})
}

fn identity_pose(p: &Vector3<f64>) -> Value {
    json!({"position": vec3(p), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}})
}

/// A SceneEntity with every primitive array present (the Foxglove JSON schema requires them).
fn entity(t: f64, frame_id: &str, id: &str) -> serde_json::Map<String, Value> {
    let mut m = serde_json::Map::new();
    m.insert("timestamp".into(), time(t));
    m.insert("frame_id".into(), json!(frame_id));
    m.insert("id".into(), json!(id));
    m.insert("lifetime".into(), json!({"sec": 0, "nsec": 0}));
    m.insert("frame_locked".into(), json!(false));
    m.insert("metadata".into(), json!([]));
    for k in [
        "arrows",
        "cubes",
        "spheres",
        "cylinders",
        "lines",
        "triangles",
        "texts",
        "models",
    ] {
        m.insert(k.into(), json!([]));
    }
    m
}

fn arm_entity(t: f64, id: &str, pose: &[f64; 9], rgb: [f64; 3], alpha: f64) -> Value {
    let mut e = entity(t, "world", id);
    let j: Vec<Vector3<f64>> = (0..3)
        .map(|k| Vector3::new(pose[3 * k], pose[3 * k + 1], pose[3 * k + 2]))
        .collect();
    let spheres: Vec<Value> = j
        .iter()
        .zip([0.07, 0.06, 0.03])
        .map(|(p, d)| json!({"pose": identity_pose(p), "size": {"x": d, "y": d, "z": d}, "color": colour(rgb, alpha)}))
        .collect();
    let mut cylinders = Vec::new();
    for (a, b, d) in [(j[0], j[1], 0.08), (j[1], j[2], 0.06)] {
        let axis = b - a;
        let len = axis.norm();
        if !(len.is_finite() && len > 1e-9) {
            continue;
        }
        let q = UnitQuaternion::rotation_between(&Vector3::z(), &axis).unwrap_or_else(|| {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        });
        cylinders.push(json!({
            "pose": {"position": vec3(&((a + b) / 2.0)), "orientation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w}},
            "size": {"x": d, "y": d, "z": len},
            "bottom_scale": 1.0,
            "top_scale": 1.0,
            "color": colour(rgb, alpha),
        }));
    }
    e.insert("spheres".into(), Value::Array(spheres));
    e.insert("cylinders".into(), Value::Array(cylinders));
    Value::Object(e)
}

impl TrackWriter {
    /// Creates `path` (under a temporary name until [`TrackWriter::finish`]); `images` adds the
    /// camera topics.
    pub fn create(path: &Path, scene: &Scene, images: bool) -> Result<Self> {
        let tmp = temp_path(path);
        let file = File::create(&tmp).map_err(|e| Error::write(path, e))?;
        let guard = crate::track_csv::TempGuard::new(&tmp);
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(format!("actrack {}", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(1 << 20));
        let mut w = opts
            .create(BufWriter::new(file))
            .map_err(|e| mcap_err(&tmp, &e))?;
        let mut add = |name: &str, schema: &Value, topic: &str| -> Result<u16> {
            let data = serde_json::to_vec(schema).map_err(|e| Error::write(&tmp, e.into()))?;
            let sid = w
                .add_schema(name, "jsonschema", &data)
                .map_err(|e| mcap_err(&tmp, &e))?;
            w.add_channel(sid, topic, "json", &BTreeMap::new())
                .map_err(|e| mcap_err(&tmp, &e))
        };
        let ch = Channels {
            tf: add(
                "foxglove.FrameTransforms",
                &schemas::frame_transforms(),
                "/tf",
            )?,
            arm: add(
                "foxglove.SceneUpdate",
                &schemas::scene_update(),
                "/actrack/arm",
            )?,
            particles: add(
                "foxglove.SceneUpdate",
                &schemas::scene_update(),
                "/actrack/particles",
            )?,
            estimate: add(
                "actrack.Estimate",
                &schemas::estimate(),
                "/actrack/estimate",
            )?,
            image: if images {
                add(
                    "foxglove.CompressedImage",
                    &schemas::compressed_image(),
                    "/camera/image",
                )?
            } else {
                0
            },
            calibration: if images {
                add(
                    "foxglove.CameraCalibration",
                    &schemas::camera_calibration(),
                    "/camera/calibration",
                )?
            } else {
                0
            },
            contour: if images {
                add(
                    "foxglove.ImageAnnotations",
                    &schemas::image_annotations(),
                    "/actrack/contour",
                )?
            } else {
                0
            },
        };
        Ok(Self {
            w,
            ch,
            tmp,
            path: path.to_path_buf(),
            scene: scene.clone(),
            seq: 0,
            images,
            frames: 0,
            guard,
        })
    }

    fn put(&mut self, channel: u16, t: f64, msg: &Value) -> Result<()> {
        let data = serde_json::to_vec(msg).map_err(|e| Error::write(&self.tmp, e.into()))?;
        let ns = (t.max(0.0) * 1e9).round() as u64;
        self.seq += 1;
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: self.seq,
            log_time: ns,
            publish_time: ns,
        };
        self.w
            .write_to_known_channel(&header, &data)
            .map_err(|e| mcap_err(&self.tmp, &e))
    }

    fn transforms(&self, t: f64) -> Value {
        let s = &self.scene;
        let mut tf = vec![
            json!({"timestamp": time(t), "parent_frame_id": "world", "child_frame_id": "table",
                   "translation": vec3(&s.table.placement.origin), "rotation": quat(&s.table.placement.rotation())}),
            json!({"timestamp": time(t), "parent_frame_id": "world", "child_frame_id": "actor",
                   "translation": vec3(&s.actor.origin), "rotation": quat(&s.actor.rotation())}),
        ];
        for c in &s.cameras {
            tf.push(json!({"timestamp": time(t), "parent_frame_id": "world", "child_frame_id": c.name,
                           "translation": vec3(&c.centre()), "rotation": quat(&c.r_cw().transpose())}));
        }
        json!({ "transforms": tf })
    }

    /// Writes one frame's messages.
    pub fn write_frame(&mut self, f: &FrameRecord<'_>) -> Result<()> {
        let t = f.time;
        let tf = self.transforms(t);
        self.put(self.ch.tf, t, &tf)?;
        let mut table = entity(t, "table", "table");
        let [hx, hy] = self.scene.table.half_extents;
        table.insert(
            "cubes".into(),
            json!([{"pose": identity_pose(&Vector3::new(0.0, 0.0, -0.002)), "size": {"x": 2.0 * hx, "y": 2.0 * hy, "z": 0.004},
                    "color": colour([0.6, 0.45, 0.3], 0.5)}]),
        );
        let arm = json!({"deletions": [], "entities": [
            arm_entity(t, "best", &f.best_pose, [0.95, 0.55, 0.1], 0.6),
            arm_entity(t, "smoothed", &f.smoothed_pose, [0.1, 0.5, 0.95], 0.9),
            Value::Object(table),
        ]});
        self.put(self.ch.arm, t, &arm)?;
        let mut seen = std::collections::BTreeSet::new();
        let mut spheres = Vec::new();
        for (a, p) in f.particles {
            let key = (*a, (p[0] * 1e4).round() as i64, (p[1] * 1e4).round() as i64);
            if seen.insert(key) {
                let c = ACTION_COLOURS[a % ACTION_COLOURS.len()];
                spheres.push(json!({"pose": identity_pose(&Vector3::from(*p)), "size": {"x": 0.012, "y": 0.012, "z": 0.012}, "color": colour(c, 0.8)}));
            }
        }
        let mut cloud = entity(t, "world", "particles");
        cloud.insert("spheres".into(), Value::Array(spheres));
        self.put(
            self.ch.particles,
            t,
            &json!({"deletions": [], "entities": [Value::Object(cloud)]}),
        )?;
        let est =
            serde_json::to_value(f.estimate).map_err(|e| Error::write(&self.tmp, e.into()))?;
        self.put(self.ch.estimate, t, &est)?;
        if self.images {
            let cam = self.scene.cameras[0].clone();
            if let Some(png) = f.png {
                let msg = json!({"timestamp": time(t), "frame_id": cam.name, "format": "png", "data": base64(png)});
                self.put(self.ch.image, t, &msg)?;
            }
            let (fx, fy, cx, cy) = (cam.model.fx, cam.model.fy, cam.model.cx, cam.model.cy);
            let calib = json!({"timestamp": time(t), "frame_id": cam.name, "width": cam.model.width, "height": cam.model.height,
                "distortion_model": "plumb_bob", "D": cam.model.distortion,
                "K": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                "P": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]});
            self.put(self.ch.calibration, t, &calib)?;
            let pts: Vec<Value> = f
                .contour
                .unwrap_or(&[])
                .iter()
                .map(|p| json!({"x": p[0], "y": p[1]}))
                .collect();
            let points = json!([{"timestamp": time(t), "type": 1, "points": pts, "outline_color": colour([1.0, 0.9, 0.1], 1.0),
                "outline_colors": [], "fill_color": colour([1.0, 0.9, 0.1], 1.0), "thickness": 2.0}]);
            let circles: Vec<Value> = f
                .theta_dot
                .iter()
                .map(|(p, c)| json!({"timestamp": time(t), "position": {"x": p[0], "y": p[1]}, "diameter": 12.0, "thickness": 2.0,
                    "fill_color": colour(*c, 1.0), "outline_color": colour([0.0, 0.0, 0.0], 1.0)}))
                .collect();
            self.put(
                self.ch.contour,
                t,
                &json!({"circles": circles, "points": points, "texts": []}),
            )?;
        }
        self.frames += 1;
        Ok(())
    }

    /// Number of frames written.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Writes the effective tracking configuration as a metadata record `actrack.config`
    /// (key `toml`: the [`crate::TrackConfig`] as TOML), so that the track can be reproduced.
    pub fn write_config(&mut self, config: &crate::config::TrackConfig) -> Result<()> {
        let mut metadata = BTreeMap::new();
        metadata.insert("toml".to_string(), config.to_toml());
        metadata.insert("version".to_string(), env!("CARGO_PKG_VERSION").to_string());
        self.w
            .write_metadata(&mcap::records::Metadata {
                name: "actrack.config".into(),
                metadata,
            })
            .map_err(|e| mcap_err(&self.tmp, &e))
    }

    /// Finishes the file (summary and indexes) and renames it into place.
    pub fn finish(mut self) -> Result<()> {
        self.w.finish().map_err(|e| mcap_err(&self.tmp, &e))?;
        drop(self.w);
        std::fs::rename(&self.tmp, &self.path).map_err(|e| Error::write(&self.path, e))?;
        self.guard.keep();
        Ok(())
    }
}

/// Standard base64 (RFC 4648 with padding), as Foxglove's JSON encoding expects for bytes.
pub fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let b = [
            c[0],
            c.get(1).copied().unwrap_or(0),
            c.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// JSON schemas of the messages, written from the Foxglove message definitions.
pub mod schemas {
    use serde_json::{Value, json};

    fn num() -> Value {
        json!({"type": "number"})
    }
    fn time() -> Value {
        json!({"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0}}, "required": ["sec", "nsec"]})
    }
    fn vec3() -> Value {
        json!({"type": "object", "properties": {"x": num(), "y": num(), "z": num()}, "required": ["x", "y", "z"]})
    }
    fn quat() -> Value {
        json!({"type": "object", "properties": {"x": num(), "y": num(), "z": num(), "w": num()}, "required": ["x", "y", "z", "w"]})
    }
    fn colour() -> Value {
        json!({"type": "object", "properties": {"r": num(), "g": num(), "b": num(), "a": num()}, "required": ["r", "g", "b", "a"]})
    }
    fn pose() -> Value {
        json!({"type": "object", "properties": {"position": vec3(), "orientation": quat()}, "required": ["position", "orientation"]})
    }
    fn obj(props: &[(&str, Value)]) -> Value {
        let mut p = serde_json::Map::new();
        for (k, v) in props {
            p.insert((*k).to_string(), v.clone());
        }
        let req: Vec<&str> = props.iter().map(|(k, _)| *k).collect();
        json!({"type": "object", "properties": p, "required": req})
    }
    #[allow(clippy::needless_pass_by_value)]
    fn arr(items: Value) -> Value {
        json!({"type": "array", "items": items})
    }

    /// foxglove.FrameTransforms
    pub fn frame_transforms() -> Value {
        let tf = obj(&[
            ("timestamp", time()),
            ("parent_frame_id", json!({"type": "string"})),
            ("child_frame_id", json!({"type": "string"})),
            ("translation", vec3()),
            ("rotation", quat()),
        ]);
        let mut s = obj(&[("transforms", arr(tf))]);
        s["title"] = json!("foxglove.FrameTransforms");
        s
    }

    /// foxglove.SceneUpdate
    pub fn scene_update() -> Value {
        let sphere = obj(&[("pose", pose()), ("size", vec3()), ("color", colour())]);
        let cube = sphere.clone();
        let cylinder = obj(&[
            ("pose", pose()),
            ("size", vec3()),
            ("bottom_scale", num()),
            ("top_scale", num()),
            ("color", colour()),
        ]);
        let arrow = obj(&[
            ("pose", pose()),
            ("shaft_length", num()),
            ("shaft_diameter", num()),
            ("head_length", num()),
            ("head_diameter", num()),
            ("color", colour()),
        ]);
        let line = obj(&[
            ("type", json!({"type": "integer", "enum": [0, 1, 2]})),
            ("pose", pose()),
            ("thickness", num()),
            ("scale_invariant", json!({"type": "boolean"})),
            ("points", arr(vec3())),
            ("color", colour()),
            ("colors", arr(colour())),
            ("indices", arr(json!({"type": "integer", "minimum": 0}))),
        ]);
        let triangles = obj(&[
            ("pose", pose()),
            ("points", arr(vec3())),
            ("color", colour()),
            ("colors", arr(colour())),
            ("indices", arr(json!({"type": "integer", "minimum": 0}))),
        ]);
        let text = obj(&[
            ("pose", pose()),
            ("billboard", json!({"type": "boolean"})),
            ("font_size", num()),
            ("scale_invariant", json!({"type": "boolean"})),
            ("color", colour()),
            ("text", json!({"type": "string"})),
        ]);
        let model = obj(&[
            ("pose", pose()),
            ("scale", vec3()),
            ("color", colour()),
            ("override_color", json!({"type": "boolean"})),
            ("url", json!({"type": "string"})),
            ("media_type", json!({"type": "string"})),
            (
                "data",
                json!({"type": "string", "contentEncoding": "base64"}),
            ),
        ]);
        let entity = obj(&[
            ("timestamp", time()),
            ("frame_id", json!({"type": "string"})),
            ("id", json!({"type": "string"})),
            ("lifetime", time()),
            ("frame_locked", json!({"type": "boolean"})),
            (
                "metadata",
                arr(obj(&[
                    ("key", json!({"type": "string"})),
                    ("value", json!({"type": "string"})),
                ])),
            ),
            ("arrows", arr(arrow)),
            ("cubes", arr(cube)),
            ("spheres", arr(sphere)),
            ("cylinders", arr(cylinder)),
            ("lines", arr(line)),
            ("triangles", arr(triangles)),
            ("texts", arr(text)),
            ("models", arr(model)),
        ]);
        let deletion = obj(&[
            ("timestamp", time()),
            ("type", json!({"type": "integer", "enum": [0, 1]})),
            ("id", json!({"type": "string"})),
        ]);
        let mut s = obj(&[("deletions", arr(deletion)), ("entities", arr(entity))]);
        s["title"] = json!("foxglove.SceneUpdate");
        s
    }

    /// foxglove.CompressedImage
    pub fn compressed_image() -> Value {
        let mut s = obj(&[
            ("timestamp", time()),
            ("frame_id", json!({"type": "string"})),
            (
                "data",
                json!({"type": "string", "contentEncoding": "base64"}),
            ),
            ("format", json!({"type": "string"})),
        ]);
        s["title"] = json!("foxglove.CompressedImage");
        s
    }

    /// foxglove.CameraCalibration
    pub fn camera_calibration() -> Value {
        let fixed = |n: usize| json!({"type": "array", "items": {"type": "number"}, "minItems": n, "maxItems": n});
        let mut s = obj(&[
            ("timestamp", time()),
            ("frame_id", json!({"type": "string"})),
            ("width", json!({"type": "integer", "minimum": 0})),
            ("height", json!({"type": "integer", "minimum": 0})),
            ("distortion_model", json!({"type": "string"})),
            ("D", arr(num())),
            ("K", fixed(9)),
            ("R", fixed(9)),
            ("P", fixed(12)),
        ]);
        s["title"] = json!("foxglove.CameraCalibration");
        s
    }

    /// foxglove.ImageAnnotations
    pub fn image_annotations() -> Value {
        let p2 = obj(&[("x", num()), ("y", num())]);
        let circle = obj(&[
            ("timestamp", time()),
            ("position", p2.clone()),
            ("diameter", num()),
            ("thickness", num()),
            ("fill_color", colour()),
            ("outline_color", colour()),
        ]);
        let points = obj(&[
            ("timestamp", time()),
            ("type", json!({"type": "integer", "enum": [0, 1, 2, 3, 4]})),
            ("points", arr(p2.clone())),
            ("outline_color", colour()),
            ("outline_colors", arr(colour())),
            ("fill_color", colour()),
            ("thickness", num()),
        ]);
        let text = obj(&[
            ("timestamp", time()),
            ("position", p2),
            ("text", json!({"type": "string"})),
            ("font_size", num()),
            ("text_color", colour()),
            ("background_color", colour()),
        ]);
        let mut s = obj(&[
            ("circles", arr(circle)),
            ("points", arr(points)),
            ("texts", arr(text)),
        ]);
        s["title"] = json!("foxglove.ImageAnnotations");
        s
    }

    /// actrack.Estimate (this project's own schema).
    pub fn estimate() -> Value {
        let n2 =
            json!({"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2});
        let mut s = obj(&[
            ("frame_id", json!({"type": "string", "minLength": 1})),
            ("frame", json!({"type": "integer", "minimum": 0})),
            ("time", num()),
            ("actions", arr(json!({"type": "string"}))),
            ("action_posterior", arr(num())),
            ("map_action", json!({"type": "string"})),
            ("theta_mean", n2.clone()),
            ("theta_std", n2),
            (
                "theta_world",
                json!({"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}),
            ),
            ("theta_entropy", num()),
            ("action_entropy", num()),
            ("ess", num()),
            ("k", num()),
            ("progress", num()),
        ]);
        s["title"] = json!("actrack.Estimate");
        s["description"] = json!(
            "Per-frame estimate of the action-space particle filter (θ in metres, actor frame)"
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_rfc4648() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn writes_a_readable_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("t.mcap");
        let scene = crate::scene::default_scene(64, 48);
        let mut w = TrackWriter::create(&p, &scene, true).unwrap();
        let est = EstimateMsg {
            frame_id: "actor".into(),
            frame: 0,
            time: 0.0,
            actions: vec!["a".into()],
            action_posterior: vec![1.0],
            map_action: "a".into(),
            theta_mean: [0.0, 0.4],
            theta_std: [0.1, 0.1],
            theta_world: [0.0, 0.5, 0.75],
            theta_entropy: 0.5,
            action_entropy: 0.0,
            ess: 10.0,
            k: 1.0,
            progress: 0.0,
        };
        for k in 0..3 {
            let pose = [0.0, 0.0, 1.1, 0.0, 0.1, 0.8, 0.0, 0.5, 0.76];
            w.write_frame(&FrameRecord {
                frame: k,
                time: k as f64 / 30.0,
                best_pose: pose,
                smoothed_pose: pose,
                particles: &[(0, [0.0, 0.5, 0.75])],
                estimate: &est,
                png: Some(&[1, 2, 3]),
                contour: Some(&[[1.0, 2.0]]),
                theta_dot: Some(([3.0, 4.0], [1.0, 0.0, 0.0])),
            })
            .unwrap();
        }
        assert!(!p.exists());
        w.finish().unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let n = mcap::MessageStream::new(&bytes).unwrap().count();
        assert_eq!(n, 3 * 7);
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert!(!summary.chunk_indexes.is_empty());
    }
}
