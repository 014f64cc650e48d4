//! The scene file (TOML): cameras, the table region, the actor's placement and (optionally) the
//! arm geometry used for rendering and the edge-image parameters. See DESIGN.md "File formats".
//!
//! ```toml
//! [[camera]]
//! name = "front"                 # optional; default "camera<i>" (also the MCAP frame id)
//! width = 640
//! height = 480
//! fx = 600.0
//! fy = 600.0
//! cx = 319.5
//! cy = 239.5
//! # optional Brown distortion: k1, k2, p1, p2, k3 (default 0)
//! # world → camera rotation R_cw (X_c = R_cw X_w + t_cw), exactly one of:
//! #   rotation = [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]]   (rows)
//! #   axis_angle = [rx, ry, rz]        (Rodrigues vector of R_cw, radians)
//! #   quaternion = [w, x, y, z]        (unit quaternion of R_cw)
//! #   look_at = { eye = [..], target = [..], up = [0, 0, 1] }   (then no `translation`)
//! translation = [0.0, 0.0, 2.0]  # t_cw, metres
//!
//! [table]
//! centre = [0.0, 0.5]            # world x, y of the region's centre, metres
//! height = 0.75                  # world z of the table surface
//! yaw_deg = 0.0                  # angle of the table's x axis from world x, about +z
//! half_extents = [0.4, 0.15]     # along the table's x and y axes, metres
//!
//! [actor]
//! origin = [0.0, 0.0, 1.1]       # world position of the acting shoulder at rest
//! yaw_deg = 0.0                  # heading of the actor frame (default: the table's)
//! arm = "right"                  # acting arm: "right" or "left" (left: the actor frame's x is mirrored)
//!
//! [arm]                          # optional rendering geometry (defaults of SPEC §4.2)
//! upper_arm_radii = [0.05, 0.04]
//! forearm_radii = [0.04, 0.03]
//! hand_half_axes = [0.09, 0.045, 0.015]
//! forearm_fraction = 0.6
//! # upper_arm_length / lower_arm_length: override the model's arm lengths
//!
//! [edges]                        # optional edge-image parameters (SPEC §4.1)
//! tau = 0.2                      # threshold τ in (0, 1]: gradients above τ·max count as edges
//! # sigma_px = 4.0               # σ_G in pixels (default 4 px at 640 px, scaled with the width)
//! binary = false                 # zero the gradients below τ (bodytrack's binary map)
//! ```
//!
//! The actor frame has its origin at `actor.origin` and the axes of the heading: x =
//! (cos ψ, sin ψ, 0), y = (−sin ψ, cos ψ, 0) (across the table, away from the actor), z up; for a
//! left arm x is negated (a mirror image), so right-arm models track the left arm.

use std::path::Path;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Raw `[[camera]]` table of the scene file.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraToml {
    /// Camera name (frame id), default `camera<i>`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along u, pixels.
    pub fx: f64,
    /// Focal length along v, pixels.
    pub fy: f64,
    /// Principal point u.
    pub cx: f64,
    /// Principal point v.
    pub cy: f64,
    /// Radial distortion k1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k1: Option<f64>,
    /// Radial distortion k2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k2: Option<f64>,
    /// Tangential distortion p1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p1: Option<f64>,
    /// Tangential distortion p2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p2: Option<f64>,
    /// Radial distortion k3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k3: Option<f64>,
    /// R_cw as three rows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[[f64; 3]; 3]>,
    /// R_cw as a Rodrigues vector (radians).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis_angle: Option<[f64; 3]>,
    /// R_cw as a unit quaternion (w, x, y, z).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quaternion: Option<[f64; 4]>,
    /// Camera placement by eye, target and up (world); replaces rotation and translation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look_at: Option<LookAtToml>,
    /// t_cw, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation: Option<[f64; 3]>,
}

/// `look_at = { eye, target, up }` of a camera.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LookAtToml {
    /// Camera centre in the world.
    pub eye: [f64; 3],
    /// A world point on the optical axis.
    pub target: [f64; 3],
    /// World "up" (default +z); the image's v axis points away from it.
    #[serde(default = "default_up")]
    pub up: [f64; 3],
}

fn default_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// Raw `[table]` of the scene file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableToml {
    /// World x, y of the region's centre.
    pub centre: [f64; 2],
    /// World z of the table surface.
    pub height: f64,
    /// Angle of the table's x axis from world x (degrees, about +z).
    #[serde(default)]
    pub yaw_deg: f64,
    /// Half-extents along the table's x and y axes.
    pub half_extents: [f64; 2],
}

/// Raw `[actor]` of the scene file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActorToml {
    /// World position of the actor frame's origin (the acting shoulder at rest).
    pub origin: [f64; 3],
    /// Heading (degrees); default: the table's yaw.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yaw_deg: Option<f64>,
    /// Acting arm.
    #[serde(default)]
    pub arm: Side,
}

/// Which arm acts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// The right arm (default).
    #[default]
    Right,
    /// The left arm.
    Left,
}

/// Optional `[arm]` rendering geometry (SPEC §4.2 defaults when absent).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArmSettings {
    /// Upper-arm radii at shoulder and elbow, metres.
    #[serde(default = "d_upper")]
    pub upper_arm_radii: [f64; 2],
    /// Forearm radii at elbow and wrist, metres.
    #[serde(default = "d_fore")]
    pub forearm_radii: [f64; 2],
    /// Hand ellipsoid half-axes (length, width, thickness), metres.
    #[serde(default = "d_hand")]
    pub hand_half_axes: [f64; 3],
    /// Forearm length as a fraction of elbow → fingertip.
    #[serde(default = "d_frac")]
    pub forearm_fraction: f64,
    /// Override of the upper-arm length L1 (metres); default: the model's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub upper_arm_length: Option<f64>,
    /// Override of the elbow → fingertip length L2 (metres); default: the model's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lower_arm_length: Option<f64>,
}

fn d_upper() -> [f64; 2] {
    [0.05, 0.04]
}
fn d_fore() -> [f64; 2] {
    [0.04, 0.03]
}
fn d_hand() -> [f64; 3] {
    [0.09, 0.045, 0.015]
}
fn d_frac() -> f64 {
    0.6
}

impl Default for ArmSettings {
    fn default() -> Self {
        Self {
            upper_arm_radii: d_upper(),
            forearm_radii: d_fore(),
            hand_half_axes: d_hand(),
            forearm_fraction: d_frac(),
            upper_arm_length: None,
            lower_arm_length: None,
        }
    }
}

/// The scene file as written on disk.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneToml {
    /// One or more cameras.
    pub camera: Vec<CameraToml>,
    /// The table region.
    pub table: TableToml,
    /// The actor's placement.
    pub actor: ActorToml,
    /// Rendering geometry of the arm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arm: Option<ArmSettings>,
    /// Edge-image parameters of SPEC §4.1 (optional `[edges]` table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edges: Option<EdgeSettings>,
}

/// Edge-image parameters of a scene (SPEC §4.1): the threshold τ, σ_G and the binary option.
///
/// τ depends on the scene: it decides which gradients count as full edges relative to the
/// strongest gradient of the frame. On the default synthetic scene (a light arm on a brown
/// table, strongly coloured clutter), τ = 0.2 leaves the arm's own outline far below 1, and a
/// wrongly placed arm lying along the torso's and the table's edges outscores the true one;
/// τ = 0.05 fixes that (see docs/results.md and `default_scene`). Elsewhere SPEC's
/// recommendation τ = 0.2 is the default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EdgeSettings {
    /// Threshold τ on the normalised gradient magnitude, in (0, 1]; SPEC recommends 0.2.
    #[serde(default = "default_tau")]
    pub tau: f64,
    /// σ_G in pixels; default 4 px at 640 px width, scaled with each camera's width.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_px: Option<f64>,
    /// Set sub-threshold gradients to 0 (Deutscher/bodytrack binary map).
    #[serde(default)]
    pub binary: bool,
}

fn default_tau() -> f64 {
    0.2
}

impl Default for EdgeSettings {
    fn default() -> Self {
        Self {
            tau: default_tau(),
            sigma_px: None,
            binary: false,
        }
    }
}

/// A camera of the scene: the calibrated pinhole camera the renderer projects with (SPEC §4.5)
/// and its name, the frame id of its views in the MCAP track.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneCamera {
    /// Name, used as the MCAP frame id.
    pub name: String,
    /// Size, intrinsics, distortion and world → camera pose.
    pub model: actrack_render::Camera,
}

impl SceneCamera {
    /// A distortion-free camera of `width`×`height` pixels with focal length `f` (pixels) in
    /// both axes, its principal point at the image centre, and the world → camera pose
    /// (`r_cw`, `t_cw`).
    pub fn centred(
        name: &str,
        (width, height): (u32, u32),
        f: f64,
        (r_cw, t_cw): (Matrix3<f64>, Vector3<f64>),
    ) -> Self {
        Self::new(
            name,
            (width, height),
            [
                f,
                f,
                (f64::from(width) - 1.0) / 2.0,
                (f64::from(height) - 1.0) / 2.0,
            ],
            [0.0; 5],
            (r_cw, t_cw),
        )
    }

    /// A camera of `width`×`height` pixels with intrinsics `[fx, fy, cx, cy]` (pixels),
    /// Brown distortion `[k1, k2, p1, p2, k3]` and the world → camera pose (`r_cw`, `t_cw`).
    pub fn new(
        name: &str,
        (width, height): (u32, u32),
        [fx, fy, cx, cy]: [f64; 4],
        distortion: [f64; 5],
        (r_cw, t_cw): (Matrix3<f64>, Vector3<f64>),
    ) -> Self {
        Self {
            name: name.into(),
            model: actrack_render::Camera {
                width,
                height,
                fx,
                fy,
                cx,
                cy,
                distortion,
                rotation: [[0.0; 3]; 3],
                translation: [0.0; 3],
            },
        }
        .posed((r_cw, t_cw))
    }

    fn posed(mut self, pose: (Matrix3<f64>, Vector3<f64>)) -> Self {
        self.set_pose(pose);
        self
    }

    /// Moves the camera to the world → camera pose (`r_cw`, `t_cw`).
    pub fn set_pose(&mut self, (r_cw, t_cw): (Matrix3<f64>, Vector3<f64>)) {
        self.model.rotation = [0, 1, 2].map(|i| [r_cw[(i, 0)], r_cw[(i, 1)], r_cw[(i, 2)]]);
        self.model.translation = [t_cw.x, t_cw.y, t_cw.z];
    }

    /// World → camera rotation R_cw.
    pub fn r_cw(&self) -> Matrix3<f64> {
        self.model.rotation_matrix()
    }

    /// World → camera translation t_cw.
    pub fn t_cw(&self) -> Vector3<f64> {
        self.model.translation_vector()
    }

    /// Projects a world point to pixel coordinates (with distortion); `None` when it is less
    /// than 1 cm in front of the camera.
    pub fn project(&self, x_w: &Vector3<f64>) -> Option<(f64, f64)> {
        self.model.project(x_w).map(|p| (p.x, p.y))
    }

    /// `true` when (u, v) lies on the image.
    pub fn in_image(&self, u: f64, v: f64) -> bool {
        u >= -0.5
            && v >= -0.5
            && u < f64::from(self.model.width) - 0.5
            && v < f64::from(self.model.height) - 0.5
    }

    /// Camera centre in the world.
    pub fn centre(&self) -> Vector3<f64> {
        self.model.center()
    }
}

/// A rigid placement on the floor: origin and heading about +z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// World origin.
    pub origin: Vector3<f64>,
    /// Heading ψ (radians): the frame's x axis is (cos ψ, sin ψ, 0).
    pub yaw: f64,
}

impl Placement {
    /// Frame → world rotation.
    pub fn rotation(&self) -> Matrix3<f64> {
        *Rotation3::from_axis_angle(&Vector3::z_axis(), self.yaw).matrix()
    }
    /// Maps a point from this frame to the world.
    pub fn to_world(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.origin + self.rotation() * p
    }
    /// Maps a world point into this frame.
    pub fn from_world(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation().transpose() * (p - self.origin)
    }
}

/// The table region R (SPEC §3.1): a rectangle on the table plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneTable {
    /// Centre on the table surface (world) and heading of the table's axes.
    pub placement: Placement,
    /// Half-extents along the table's x and y.
    pub half_extents: [f64; 2],
}

impl SceneTable {
    /// The four corners in the world (on the table surface).
    pub fn corners(&self) -> [Vector3<f64>; 4] {
        let [hx, hy] = self.half_extents;
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .map(|(a, b)| self.placement.to_world(&Vector3::new(a * hx, b * hy, 0.0)))
    }
}

/// A validated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The cameras (at least one).
    pub cameras: Vec<SceneCamera>,
    /// The table region.
    pub table: SceneTable,
    /// The actor frame's placement in the world.
    pub actor: Placement,
    /// The acting arm.
    pub side: Side,
    /// Rendering geometry of the arm.
    pub arm: ArmSettings,
    /// Edge-image parameters (SPEC §4.1).
    pub edges: EdgeSettings,
}

impl Scene {
    /// The edge-image parameters for a camera `width` pixels wide.
    pub fn edge_params(&self, width: u32) -> actrack_render::EdgeParams {
        actrack_render::EdgeParams {
            tau: self.edges.tau as f32,
            sigma: self
                .edges
                .sigma_px
                .map_or_else(|| default_edge_sigma(width), |s| s as f32),
            binary: self.edges.binary,
            colour: false,
        }
    }

    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
        Self::parse(&text, path)
    }

    /// Parses and validates scene TOML; `path` is used in messages only.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let raw: SceneToml = toml::from_str(text).map_err(|e| {
            let line = e
                .span()
                .map_or(1, |s| text[..s.start.min(text.len())].split('\n').count());
            Error::parse(path, line, e.message().to_string())
        })?;
        Self::from_toml(&raw, path)
    }

    /// Validates a raw scene; `path` is used in messages only.
    pub fn from_toml(raw: &SceneToml, path: &Path) -> Result<Self> {
        let bad = |field: &str, msg: &str| Error::invalid(path, format!("{field}: {msg}"));
        if raw.camera.is_empty() {
            return Err(bad("camera", "at least one [[camera]] is required"));
        }
        let t = &raw.table;
        if !t.half_extents.iter().all(|h| h.is_finite() && *h > 0.0) {
            return Err(bad(
                "table.half_extents",
                "must be two positive numbers (metres)",
            ));
        }
        if !finite(&t.centre) || !t.height.is_finite() || !t.yaw_deg.is_finite() {
            return Err(bad("table", "centre, height and yaw_deg must be finite"));
        }
        let table = SceneTable {
            placement: Placement {
                origin: Vector3::new(t.centre[0], t.centre[1], t.height),
                yaw: t.yaw_deg.to_radians(),
            },
            half_extents: t.half_extents,
        };
        let a = &raw.actor;
        if !finite(&a.origin) || !a.yaw_deg.is_none_or(f64::is_finite) {
            return Err(bad("actor", "origin and yaw_deg must be finite"));
        }
        let actor = Placement {
            origin: Vector3::from(a.origin),
            yaw: a.yaw_deg.unwrap_or(t.yaw_deg).to_radians(),
        };
        let arm = raw.arm.clone().unwrap_or_default();
        let pos = |v: &[f64]| v.iter().all(|x| x.is_finite() && *x > 0.0);
        if !pos(&arm.upper_arm_radii)
            || !pos(&arm.forearm_radii)
            || !pos(&arm.hand_half_axes)
            || !pos(&[arm.forearm_fraction, 1.0 - arm.forearm_fraction])
            || !pos(&[
                arm.upper_arm_length.unwrap_or(1.0),
                arm.lower_arm_length.unwrap_or(1.0),
            ])
        {
            return Err(bad(
                "arm",
                "radii, half-axes and lengths must be positive, forearm_fraction in (0, 1)",
            ));
        }
        let edges = raw.edges.clone().unwrap_or_default();
        if !(edges.tau.is_finite() && edges.tau > 0.0 && edges.tau <= 1.0) {
            return Err(bad("edges.tau", "must be in (0, 1] (SPEC default 0.2)"));
        }
        if !edges
            .sigma_px
            .is_none_or(|s| s.is_finite() && (0.0..=64.0).contains(&s))
        {
            return Err(bad("edges.sigma_px", "must be in [0, 64] pixels"));
        }
        let mut cameras = Vec::with_capacity(raw.camera.len());
        for (i, c) in raw.camera.iter().enumerate() {
            cameras.push(camera_from_toml(c, i, path)?);
        }
        for (i, c) in cameras.iter().enumerate() {
            if cameras[..i].iter().any(|o| o.name == c.name) {
                return Err(bad(
                    &format!("camera[{i}].name"),
                    &format!("duplicate name `{}`", c.name),
                ));
            }
        }
        let scene = Scene {
            cameras,
            table,
            actor,
            side: a.arm,
            arm,
            edges,
        };
        for (i, c) in scene.cameras.iter().enumerate() {
            let centre = scene.table.placement.origin;
            let sees = c.project(&centre).is_some_and(|(u, v)| c.in_image(u, v));
            if !sees {
                return Err(bad(
                    &format!("camera[{i}] (`{}`)", c.name),
                    "does not see the table: the table centre is behind the camera or outside the image",
                ));
            }
        }
        check_plausible(&scene, path)?;
        Ok(scene)
    }

    /// Serialises the scene back to TOML (rotation as rows).
    pub fn to_toml_string(&self) -> String {
        let raw = SceneToml {
            camera: self
                .cameras
                .iter()
                .map(|c| {
                    let m = &c.model;
                    let nz = |x: f64| (x != 0.0).then_some(x);
                    CameraToml {
                        name: Some(c.name.clone()),
                        width: m.width,
                        height: m.height,
                        fx: m.fx,
                        fy: m.fy,
                        cx: m.cx,
                        cy: m.cy,
                        k1: nz(m.distortion[0]),
                        k2: nz(m.distortion[1]),
                        p1: nz(m.distortion[2]),
                        p2: nz(m.distortion[3]),
                        k3: nz(m.distortion[4]),
                        rotation: Some(m.rotation),
                        translation: Some(m.translation),
                        ..CameraToml::default()
                    }
                })
                .collect(),
            table: TableToml {
                centre: [self.table.placement.origin.x, self.table.placement.origin.y],
                height: self.table.placement.origin.z,
                yaw_deg: self.table.placement.yaw.to_degrees(),
                half_extents: self.table.half_extents,
            },
            actor: ActorToml {
                origin: self.actor.origin.into(),
                yaw_deg: Some(self.actor.yaw.to_degrees()),
                arm: self.side,
            },
            arm: Some(self.arm.clone()),
            edges: (self.edges != EdgeSettings::default()).then(|| self.edges.clone()),
        };
        toml::to_string_pretty(&raw).unwrap_or_default()
    }

    /// −1 for a left arm, else 1: the sign of the actor frame's x axis. A left arm's actor frame
    /// is mirrored (x points to the actor's left), so models of the right arm (and left arms
    /// mirrored onto it in training) track either arm.
    pub fn mirror(&self) -> f64 {
        if self.side == Side::Left { -1.0 } else { 1.0 }
    }

    /// The θ prior region in the actor frame: (centre, half-extents) of the axis-aligned box
    /// bounding the table region (exact when the actor's heading equals the table's).
    pub fn theta_region(&self) -> ([f64; 2], [f64; 2]) {
        let c = self.actor.from_world(&self.table.placement.origin);
        let corners = self.table.corners().map(|p| self.actor.from_world(&p));
        let mut h = [0.0_f64; 2];
        for p in &corners {
            h[0] = h[0].max((p.x - c.x).abs());
            h[1] = h[1].max((p.y - c.y).abs());
        }
        ([self.mirror() * c.x, c.y], h)
    }

    /// The world point on the table surface of θ (actor-frame x, y).
    pub fn theta_to_world(&self, theta: [f64; 2]) -> Vector3<f64> {
        let z = self.table.placement.origin.z - self.actor.origin.z;
        self.actor
            .to_world(&Vector3::new(self.mirror() * theta[0], theta[1], z))
    }

    /// The table surface's height in the actor frame (metres; negative: below the shoulder),
    /// the floor of `track --fingertip-floor table`.
    pub fn table_height(&self) -> f64 {
        self.actor.from_world(&self.table.placement.origin).z
    }

    /// Maps an actor-frame pose (p, q, r) to world coordinates.
    pub fn pose_to_world(&self, pose: &[f64; 9]) -> [f64; 9] {
        let mut out = [0.0; 9];
        for j in 0..3 {
            let w = self.actor.to_world(&Vector3::new(
                self.mirror() * pose[3 * j],
                pose[3 * j + 1],
                pose[3 * j + 2],
            ));
            out[3 * j..3 * j + 3].copy_from_slice(w.as_slice());
        }
        out
    }

    /// Maps a world pose (p, q, r) into the actor frame.
    pub fn pose_to_actor(&self, pose: &[f64; 9]) -> [f64; 9] {
        let mut out = [0.0; 9];
        for j in 0..3 {
            let a =
                self.actor
                    .from_world(&Vector3::new(pose[3 * j], pose[3 * j + 1], pose[3 * j + 2]));
            out[3 * j..3 * j + 3].copy_from_slice(&[self.mirror() * a.x, a.y, a.z]);
        }
        out
    }
}

/// Camera distance to the table centre a tracking setup can have (metres).
pub const CAMERA_DISTANCE_RANGE: (f64, f64) = (0.3, 20.0);
/// Least elevation (degrees) of a camera above the table plane, seen from the table centre:
/// lower, the table plane (where θ lives) is seen edge-on.
pub const MIN_CAMERA_ELEVATION_DEG: f64 = 10.0;
/// Farthest the actor's shoulder may be from the nearest point of the table region (metres):
/// a seated adult reaches about 0.7 m.
pub const MAX_ACTOR_TABLE_DISTANCE: f64 = 1.0;
/// Segment lengths (metres) a human arm has (upper arm, elbow → fingertip).
pub const ARM_LENGTH_RANGE: (f64, f64) = (0.1, 1.0);
/// Largest arm radius or hand half-axis (metres).
pub const MAX_ARM_THICKNESS: f64 = 0.3;

/// Plausibility of a well-typed scene: cameras at a distance and height from which the table
/// is seen, the actor within reach of the table, an arm of human size.
fn check_plausible(scene: &Scene, path: &Path) -> Result<()> {
    let bad = |field: &str, msg: String| Error::invalid(path, format!("{field}: {msg}"));
    let centre = scene.table.placement.origin;
    for (i, c) in scene.cameras.iter().enumerate() {
        let eye = c.centre();
        let d = (eye - centre).norm();
        let (lo, hi) = CAMERA_DISTANCE_RANGE;
        if !(lo..=hi).contains(&d) {
            return Err(bad(
                &format!("camera[{i}] (`{}`)", c.name),
                format!(
                    "{d:.2} m from the table centre; a camera filming an arm at a table is \
                     {lo}–{hi} m away (are the units metres?)"
                ),
            ));
        }
        let above = eye.z - centre.z;
        let elevation = (above / d).asin().to_degrees();
        if elevation < MIN_CAMERA_ELEVATION_DEG {
            return Err(bad(
                &format!("camera[{i}] (`{}`)", c.name),
                format!(
                    "{above:.2} m above the table plane ({elevation:.1}° seen from the table \
                     centre): it must look down on the table from at least \
                     {MIN_CAMERA_ELEVATION_DEG}° above its plane"
                ),
            ));
        }
    }
    // Distance from the shoulder to the table region (a rectangle at the table height).
    let local = scene.table.placement.from_world(&scene.actor.origin);
    let h = scene.table.half_extents;
    let dx = (local.x.abs() - h[0]).max(0.0);
    let dy = (local.y.abs() - h[1]).max(0.0);
    let reach = (dx * dx + dy * dy + local.z * local.z).sqrt();
    if reach > MAX_ACTOR_TABLE_DISTANCE {
        return Err(bad(
            "actor.origin",
            format!(
                "the shoulder is {reach:.2} m from the nearest point of the table region; an \
                 actor works within {MAX_ACTOR_TABLE_DISTANCE} m of it"
            ),
        ));
    }
    let a = &scene.arm;
    let (lo, hi) = ARM_LENGTH_RANGE;
    for (key, v) in [
        ("arm.upper_arm_length", a.upper_arm_length),
        ("arm.lower_arm_length", a.lower_arm_length),
    ] {
        if let Some(l) = v
            && !(lo..=hi).contains(&l)
        {
            return Err(bad(
                key,
                format!("{l} m; a human arm segment is {lo}–{hi} m long"),
            ));
        }
    }
    let thick = a
        .upper_arm_radii
        .iter()
        .chain(&a.forearm_radii)
        .chain(&a.hand_half_axes)
        .fold(0.0f64, |m, v| m.max(*v));
    if thick > MAX_ARM_THICKNESS {
        return Err(bad(
            "arm",
            format!(
                "a radius or hand half-axis of {thick} m; a human arm's are below {MAX_ARM_THICKNESS} m"
            ),
        ));
    }
    Ok(())
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// R_cw and t_cw of a camera at `eye` looking at `target` with world `up` (v points away from up).
pub fn look_at(
    eye: Vector3<f64>,
    target: Vector3<f64>,
    up: Vector3<f64>,
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let z = (target - eye).try_normalize(1e-12)?;
    let x = z.cross(&up).try_normalize(1e-9)?; // image u: right
    let y = z.cross(&x); // image v: down
    let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    let t = -(r * eye);
    Some((r, t))
}

fn camera_from_toml(c: &CameraToml, i: usize, path: &Path) -> Result<SceneCamera> {
    let bad = |field: &str, msg: &str| Error::invalid(path, format!("camera[{i}].{field}: {msg}"));
    if c.width == 0 || c.height == 0 {
        return Err(bad("width/height", "must be positive"));
    }
    if !(c.fx > 0.0 && c.fy > 0.0 && c.fx.is_finite() && c.fy.is_finite()) {
        return Err(bad("fx/fy", "focal lengths must be positive pixels"));
    }
    if !c.cx.is_finite() || !c.cy.is_finite() {
        return Err(bad("cx/cy", "must be finite"));
    }
    let given = [
        c.rotation.is_some(),
        c.axis_angle.is_some(),
        c.quaternion.is_some(),
        c.look_at.is_some(),
    ]
    .iter()
    .filter(|b| **b)
    .count();
    if given != 1 {
        return Err(bad(
            "rotation",
            "give exactly one of `rotation` (3×3 rows), `axis_angle`, `quaternion` [w,x,y,z] or `look_at`",
        ));
    }
    let (r_cw, t_cw) = if let Some(la) = &c.look_at {
        if c.translation.is_some() {
            return Err(bad("translation", "not allowed together with `look_at`"));
        }
        look_at(
            Vector3::from(la.eye),
            Vector3::from(la.target),
            Vector3::from(la.up),
        )
        .ok_or_else(|| {
            bad(
                "look_at",
                "eye equals target, or the view direction is parallel to `up`",
            )
        })?
    } else {
        let t = c
            .translation
            .ok_or_else(|| bad("translation", "missing (t_cw, metres)"))?;
        if !finite(&t) {
            return Err(bad("translation", "must be finite"));
        }
        let r = if let Some(rows) = c.rotation {
            let m = Matrix3::from_fn(|a, b| rows[a][b]);
            let err = (m * m.transpose() - Matrix3::identity()).abs().max();
            if err.is_nan() || err >= 1e-4 || m.determinant() < 0.0 {
                return Err(bad(
                    "rotation",
                    "is not a rotation matrix (RᵀR ≠ I or det < 0)",
                ));
            }
            // Re-orthonormalise the rounding of a printed matrix.
            *Rotation3::from_matrix_eps(&m, 1e-12, 100, Rotation3::identity()).matrix()
        } else if let Some(aa) = c.axis_angle {
            if !finite(&aa) {
                return Err(bad("axis_angle", "must be finite"));
            }
            *Rotation3::new(Vector3::from(aa)).matrix()
        } else {
            let [w, x, y, z] = c.quaternion.unwrap_or([1.0, 0.0, 0.0, 0.0]);
            let q = nalgebra::Quaternion::new(w, x, y, z);
            let n = q.norm();
            if n.is_nan() || (n - 1.0).abs() >= 1e-3 {
                return Err(bad("quaternion", "must be a unit quaternion [w, x, y, z]"));
            }
            *UnitQuaternion::new_unchecked(q / n)
                .to_rotation_matrix()
                .matrix()
        };
        (r, Vector3::from(t))
    };
    let distortion = [c.k1, c.k2, c.p1, c.p2, c.k3].map(|v| v.unwrap_or(0.0));
    if !finite(&distortion) {
        return Err(bad("k1/k2/p1/p2/k3", "must be finite"));
    }
    Ok(SceneCamera::new(
        &c.name.clone().unwrap_or_else(|| format!("camera{i}")),
        (c.width, c.height),
        [c.fx, c.fy, c.cx, c.cy],
        distortion,
        (r_cw, t_cw),
    ))
}

/// A default synthetic scene: a 60 × 24 cm table region at 0.75 m, the actor's shoulder 0.35 m
/// above it, 0.40 m before and 0.05 m to the right of the region's centre (every corner within
/// reach of a 0.29 + 0.45 m arm), one camera of `width`×`height` looking down at the workspace
/// from above.
pub fn default_scene(width: u32, height: u32) -> Scene {
    let f = 0.9 * f64::from(width);
    // High above the far side of the table, looking down at the workspace: the table plane
    // (where θ lives) is seen nearly face-on, which makes both components of θ observable.
    let eye = Vector3::new(0.2, 0.5, 2.4);
    let target = Vector3::new(0.0, 0.35, 0.8);
    let pose =
        look_at(eye, target, Vector3::z()).unwrap_or((Matrix3::identity(), Vector3::zeros()));
    Scene {
        cameras: vec![SceneCamera::centred("camera0", (width, height), f, pose)],
        table: SceneTable {
            placement: Placement {
                origin: Vector3::new(0.0, 0.5, 0.75),
                yaw: 0.0,
            },
            half_extents: [0.3, 0.12],
        },
        actor: Placement {
            origin: Vector3::new(0.05, 0.1, 1.1),
            yaw: 0.0,
        },
        side: Side::Right,
        arm: ArmSettings::default(),
        // Below SPEC's 0.2: the rendered arm's edges against the table are weak, and higher
        // thresholds lose part of its outline.
        edges: EdgeSettings {
            tau: 0.05,
            ..EdgeSettings::default()
        },
    }
}

/// The renderer's arm geometry: the scene's radii and the model's lengths (unless the scene
/// overrides them).
pub fn render_arm(scene: &Scene, lengths: [f64; 2]) -> actrack_render::ArmGeometry {
    let a = &scene.arm;
    actrack_render::ArmGeometry {
        l1: a.upper_arm_length.unwrap_or(lengths[0]),
        l2: a.lower_arm_length.unwrap_or(lengths[1]),
        upper_radii: a.upper_arm_radii,
        forearm_radii: a.forearm_radii,
        forearm_fraction: a.forearm_fraction,
        hand_half_axes: a.hand_half_axes,
    }
}

/// Edge-image parameters for a frame width with SPEC's τ: SPEC §4.1 (σ_G = 4 px at 640 px,
/// scaled). A scene's own are [`Scene::edge_params`].
pub fn edge_params(width: u32) -> actrack_render::EdgeParams {
    actrack_render::EdgeParams {
        sigma: default_edge_sigma(width),
        ..actrack_render::EdgeParams::default()
    }
}

/// σ_G of SPEC §4.1 for an image `width` pixels wide: 4 px at 640, scaled with the width and
/// clamped to [1, 8] px.
pub fn default_edge_sigma(width: u32) -> f32 {
    (4.0 * f64::from(width) / 640.0).clamp(1.0, 8.0) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    const OK: &str = r#"
[[camera]]
name = "front"
width = 320
height = 240
fx = 300.0
fy = 300.0
cx = 159.5
cy = 119.5
look_at = { eye = [0.0, -1.0, 1.5], target = [0.0, 0.5, 0.75] }

[table]
centre = [0.0, 0.5]
height = 0.75
half_extents = [0.4, 0.15]

[actor]
origin = [0.1, 0.0, 1.1]
"#;

    #[test]
    fn parses_and_projects() {
        let s = Scene::parse(OK, Path::new("s.toml")).unwrap();
        let c = &s.cameras[0];
        let (u, v) = c.project(&Vector3::new(0.0, 0.5, 0.75)).unwrap();
        assert!((u - 159.5).abs() < 1e-9 && (v - 119.5).abs() < 1e-9);
        // Roundtrip through the TOML writer.
        let s2 = Scene::parse(&s.to_toml_string(), Path::new("s2.toml")).unwrap();
        assert!((s2.cameras[0].r_cw() - c.r_cw()).abs().max() < 1e-12);
        let (ctr, h) = s.theta_region();
        assert!((ctr[0] + 0.1).abs() < 1e-12 && (ctr[1] - 0.5).abs() < 1e-12);
        assert!((h[0] - 0.4).abs() < 1e-12 && (h[1] - 0.15).abs() < 1e-12);
        let w = s.theta_to_world([-0.1, 0.5]);
        assert!((w - Vector3::new(0.0, 0.5, 0.75)).norm() < 1e-12);
    }

    #[test]
    fn rotation_forms_agree() {
        let r = *Rotation3::new(Vector3::new(0.3, -0.2, 0.1)).matrix();
        let q = UnitQuaternion::from_matrix(&r);
        let rows = [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]);
        let mk = |f: &dyn Fn(&mut CameraToml)| {
            let mut c = CameraToml {
                width: 10,
                height: 10,
                fx: 1.0,
                fy: 1.0,
                translation: Some([0.0; 3]),
                ..Default::default()
            };
            f(&mut c);
            camera_from_toml(&c, 0, Path::new("x")).unwrap().r_cw()
        };
        let a = mk(&|c| c.rotation = Some(rows));
        let b = mk(&|c| c.axis_angle = Some([0.3, -0.2, 0.1]));
        let d = mk(&|c| c.quaternion = Some([q.w, q.i, q.j, q.k]));
        assert!((a - b).abs().max() < 1e-9 && (a - d).abs().max() < 1e-9);
    }

    #[test]
    fn errors_name_file_and_field() {
        let e = Scene::parse(
            &OK.replace("half_extents = [0.4, 0.15]", "half_extents = [0.4, -1.0]"),
            Path::new("s.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("s.toml") && e.contains("table.half_extents"),
            "{e}"
        );
        let e = Scene::parse(
            &OK.replace("target = [0.0, 0.5, 0.75]", "target = [0.0, -3.0, 1.5]"),
            Path::new("s.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("does not see the table"), "{e}");
        let e =
            Scene::parse(&OK.replace("fx = 300.0", "fx = \"a\""), Path::new("s.toml")).unwrap_err();
        assert!(matches!(e, Error::Parse { line: 6, .. }), "{e}");
        let e = Scene::parse(
            &OK.replace("width = 320", "width = 320\ntranslation = [0.0, 0.0, 0.0]"),
            Path::new("s.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("camera[0].translation"), "{e}");
    }

    #[test]
    fn edge_settings_parse_validate_and_round_trip() {
        // Absent: SPEC §4.1 defaults, σ_G scaled with the camera width.
        let s = Scene::parse(OK, Path::new("s.toml")).unwrap();
        assert_eq!(s.edges, EdgeSettings::default());
        let close = |a: f32, b: f32| (a - b).abs() < 1e-6;
        let p = s.edge_params(320);
        assert!(
            close(p.tau, 0.2) && close(p.sigma, 2.0) && !p.binary,
            "{p:?}"
        );
        assert!(close(s.edge_params(640).sigma, 4.0));
        assert!(!s.to_toml_string().contains("[edges]"));
        // Given: used as written, and written back.
        let text = format!("{OK}\n[edges]\ntau = 0.05\nsigma_px = 3.0\nbinary = true\n");
        let s = Scene::parse(&text, Path::new("s.toml")).unwrap();
        let p = s.edge_params(320);
        assert!(
            close(p.tau, 0.05) && close(p.sigma, 3.0) && p.binary,
            "{p:?}"
        );
        let back = Scene::parse(&s.to_toml_string(), Path::new("b.toml")).unwrap();
        assert_eq!(back.edges, s.edges);
        // Bad values and unknown keys name the file and the field or line.
        for (bad, what) in [
            ("tau = 0.0", "edges.tau"),
            ("tau = 1.5", "edges.tau"),
            ("sigma_px = -1.0", "edges.sigma_px"),
            ("sigma_px = nan", "edges.sigma_px"),
        ] {
            let e = Scene::parse(&format!("{OK}\n[edges]\n{bad}\n"), Path::new("s.toml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("s.toml") && e.contains(what), "{bad}: {e}");
        }
        let e = Scene::parse(
            &format!("{OK}\n[edges]\nthreshold = 0.1\n"),
            Path::new("s.toml"),
        )
        .unwrap_err();
        assert!(matches!(e, Error::Parse { .. }), "{e}");
    }

    #[test]
    fn default_scene_is_valid() {
        let s = default_scene(320, 240);
        let back = Scene::parse(&s.to_toml_string(), Path::new("d.toml")).unwrap();
        assert_eq!(back.edges, s.edges);
        for p in s.table.corners() {
            let (u, v) = s.cameras[0].project(&p).unwrap();
            assert!(s.cameras[0].in_image(u, v));
        }
        // The table surface in the actor frame: the world heights' difference (the actor's
        // heading turns about z only).
        let want = s.table.placement.origin.z - s.actor.origin.z;
        assert!((s.table_height() - want).abs() < 1e-12);
        assert!(s.table_height() < 0.0, "{}", s.table_height());
    }
}
