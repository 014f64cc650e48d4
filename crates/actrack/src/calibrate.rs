//! Scene calibration from one frame: the camera pose from the pixel positions of the table's four
//! corners (PnP on four coplanar points, refined on the reprojection error), the actor placed
//! from the acting shoulder's pixel and height, written as a [`Scene`].
//!
//! The world frame of a calibrated scene is the table's: origin below the table's centre on the
//! floor, x along the table's near edge (to the actor's right), y across the table away from the
//! actor, z up; the table surface is at `table_height`. The corners are given in the order
//! near-left, near-right, far-right, far-left as the actor sees them (the order of
//! [`crate::scene::SceneTable::corners`]).
//!
//! The pose comes from SQPnP (`sqpnp_simple`, globally optimal for any number of points including
//! the planar case) on the undistorted corners, refined by Levenberg–Marquardt on the distorted
//! pixel residuals. Input that cannot give a trustworthy pose (not four corners, a self-crossing
//! or concave quadrilateral, the table behind or above the camera, a reprojection error above the
//! threshold) is an [`Error::Config`] that says what is wrong.

use std::path::Path;

use image::{Rgb, RgbImage};
use nalgebra::{Matrix3, Matrix6, Rotation3, Vector3, Vector6};

use crate::error::{Error, Result};
use crate::scene::{ArmSettings, EdgeSettings, Placement, Scene, SceneCamera, SceneTable, Side};

/// Camera intrinsics: focal lengths and principal point in pixels, OpenCV's Brown distortion.
#[derive(Clone, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length along u, pixels.
    pub fx: f64,
    /// Focal length along v, pixels.
    pub fy: f64,
    /// Principal point u.
    pub cx: f64,
    /// Principal point v.
    pub cy: f64,
    /// Distortion (k1, k2, p1, p2, k3).
    pub distortion: [f64; 5],
    /// Image size the intrinsics were calibrated at, when the source says.
    pub size: Option<(u32, u32)>,
}

impl Intrinsics {
    /// Square pixels, principal point at the image centre, focal length `f` pixels.
    pub fn from_focal(width: u32, height: u32, f: f64) -> Result<Self> {
        if !(f.is_finite() && f > 0.0) {
            return Err(Error::Config(format!(
                "focal length must be a positive number of pixels, got {f}"
            )));
        }
        Ok(Self {
            fx: f,
            fy: f,
            cx: (f64::from(width) - 1.0) / 2.0,
            cy: (f64::from(height) - 1.0) / 2.0,
            distortion: [0.0; 5],
            size: Some((width, height)),
        })
    }

    /// Square pixels, principal point at the image centre, horizontal field of view `hfov_deg`.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Result<Self> {
        if !(hfov_deg.is_finite() && hfov_deg > 1.0 && hfov_deg < 179.0) {
            return Err(Error::Config(format!(
                "horizontal field of view must be between 1 and 179 degrees, got {hfov_deg}"
            )));
        }
        let f = f64::from(width) / 2.0 / (hfov_deg.to_radians() / 2.0).tan();
        Self::from_focal(width, height, f)
    }

    /// Reads an OpenCV calibration: a `cv::FileStorage` YAML (`camera_matrix` /
    /// `distortion_coefficients` as `!!opencv-matrix`, optional `image_width` / `image_height`)
    /// or a JSON object with `camera_matrix` (3×3 rows or 9 numbers), `dist_coeffs` (or
    /// `distortion_coefficients`, 4, 5 or more numbers: the first five are used; higher-order
    /// terms must be zero) and optional `image_width` / `image_height`.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
        let is_json = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
            || text.trim_start().starts_with('{');
        let (k, d, w, h) = if is_json {
            parse_json_intrinsics(&text, path)?
        } else {
            parse_opencv_yaml(&text, path)?
        };
        if k.len() != 9 {
            return Err(Error::invalid(
                path,
                format!("camera_matrix has {} numbers, expected 9", k.len()),
            ));
        }
        let mut distortion = [0.0; 5];
        for (i, v) in d.iter().enumerate() {
            if i < 5 {
                distortion[i] = *v;
            } else if *v != 0.0 {
                return Err(Error::invalid(
                    path,
                    format!(
                        "distortion coefficient {i} is {v}: only OpenCV's k1 k2 p1 p2 k3 are supported"
                    ),
                ));
            }
        }
        if ![k[0], k[2], k[4], k[5]]
            .iter()
            .chain(&distortion)
            .all(|v| v.is_finite())
            || k[0] <= 0.0
            || k[4] <= 0.0
        {
            return Err(Error::invalid(
                path,
                "camera_matrix needs positive finite fx, fy and finite cx, cy",
            ));
        }
        Ok(Self {
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
            size: w.zip(h),
        })
    }

    /// These intrinsics for an image of `width`×`height`: unchanged when the calibration's size
    /// is unknown or equal, scaled when the aspect ratio is the same (a resized video), an error
    /// otherwise (a cropped video needs its own calibration).
    pub fn for_size(&self, width: u32, height: u32) -> Result<Self> {
        let Some((w0, h0)) = self.size else {
            return Ok(Self {
                size: Some((width, height)),
                ..self.clone()
            });
        };
        if (w0, h0) == (width, height) {
            return Ok(self.clone());
        }
        let (sx, sy) = (
            f64::from(width) / f64::from(w0),
            f64::from(height) / f64::from(h0),
        );
        if (sx / sy - 1.0).abs() > 0.01 {
            return Err(Error::Config(format!(
                "the intrinsics are for {w0}×{h0} pixels and the image is {width}×{height}: \
                 the aspect ratio differs (cropped?), calibrate the camera at this size"
            )));
        }
        Ok(Self {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
            distortion: self.distortion,
            size: Some((width, height)),
        })
    }

    fn camera(
        &self,
        width: u32,
        height: u32,
        r_cw: Matrix3<f64>,
        t_cw: Vector3<f64>,
    ) -> SceneCamera {
        SceneCamera::new(
            "camera0",
            (width, height),
            [self.fx, self.fy, self.cx, self.cy],
            self.distortion,
            (r_cw, t_cw),
        )
    }
}

type RawIntrinsics = (Vec<f64>, Vec<f64>, Option<u32>, Option<u32>);

fn parse_json_intrinsics(text: &str, path: &Path) -> Result<RawIntrinsics> {
    let v: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| Error::parse(path, e.line(), format!("not valid JSON: {e}")))?;
    let flat = |v: &serde_json::Value| -> Option<Vec<f64>> {
        let mut out = Vec::new();
        let mut stack = vec![v];
        while let Some(x) = stack.pop() {
            match x {
                serde_json::Value::Array(a) => stack.extend(a.iter().rev()),
                serde_json::Value::Number(n) => out.push(n.as_f64()?),
                _ => return None,
            }
        }
        Some(out)
    };
    let k = ["camera_matrix", "K"]
        .iter()
        .find_map(|key| v.get(key))
        .ok_or_else(|| Error::invalid(path, "no `camera_matrix` key"))?;
    let k = flat(k).ok_or_else(|| Error::invalid(path, "camera_matrix: expected numbers"))?;
    let d = match ["dist_coeffs", "distortion_coefficients", "D"]
        .iter()
        .find_map(|key| v.get(key))
    {
        Some(d) => flat(d).ok_or_else(|| Error::invalid(path, "dist_coeffs: expected numbers"))?,
        None => Vec::new(),
    };
    let dim = |key: &str| -> Result<Option<u32>> {
        v.get(key)
            .map(|x| {
                x.as_u64()
                    .and_then(|n| u32::try_from(n).ok())
                    .ok_or_else(|| Error::invalid(path, format!("{key}: expected a pixel count")))
            })
            .transpose()
    };
    Ok((k, d, dim("image_width")?, dim("image_height")?))
}

/// The numbers of the `data: [ … ]` list of the OpenCV matrix named `key`, and its line.
fn opencv_matrix(text: &str, key: &str, path: &Path) -> Result<Option<Vec<f64>>> {
    let mut lines = text.lines().enumerate();
    while let Some((_, line)) = lines.next() {
        let t = line.trim_start();
        let Some(rest) = t.strip_prefix(key) else {
            continue;
        };
        if !rest.trim_start().starts_with(':') {
            continue;
        }
        // Collect from `data:` to the closing bracket (the list may span lines).
        let mut buf = String::new();
        let mut start = None;
        for (j, l) in lines.by_ref() {
            if start.is_none() {
                if let Some(pos) = l.find("data:") {
                    start = Some(j + 1);
                    buf.push_str(&l[pos + 5..]);
                } else {
                    continue;
                }
            } else {
                buf.push(' ');
                buf.push_str(l);
            }
            if buf.contains(']') {
                break;
            }
        }
        let line_no = start.ok_or_else(|| Error::invalid(path, format!("{key}: no `data:`")))?;
        let inner = buf
            .trim()
            .strip_prefix('[')
            .and_then(|s| s.split(']').next())
            .ok_or_else(|| Error::parse(path, line_no, format!("{key}: expected data: [ … ]")))?;
        let nums = inner
            .split(',')
            .filter(|s| !s.trim().is_empty())
            .map(|s| {
                s.trim().parse::<f64>().map_err(|_| {
                    Error::parse(
                        path,
                        line_no,
                        format!("{key}: `{}` is not a number", s.trim()),
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?;
        return Ok(Some(nums));
    }
    Ok(None)
}

fn parse_opencv_yaml(text: &str, path: &Path) -> Result<RawIntrinsics> {
    let k = opencv_matrix(text, "camera_matrix", path)?
        .ok_or_else(|| Error::invalid(path, "no `camera_matrix: !!opencv-matrix` entry"))?;
    let d = match opencv_matrix(text, "distortion_coefficients", path)? {
        Some(d) => d,
        None => opencv_matrix(text, "dist_coeffs", path)?.unwrap_or_default(),
    };
    let dim =
        |key: &str| -> Result<Option<u32>> {
            for (i, line) in text.lines().enumerate() {
                if let Some(rest) = line.trim_start().strip_prefix(key)
                    && let Some(v) = rest.trim_start().strip_prefix(':')
                {
                    return v.trim().parse::<u32>().map(Some).map_err(|_| {
                        Error::parse(path, i + 1, format!("{key}: expected an integer"))
                    });
                }
            }
            Ok(None)
        };
    Ok((k, d, dim("image_width")?, dim("image_height")?))
}

/// Parses corners from text: `u,v` pairs separated by spaces, semicolons or new lines
/// (`"12,340 610,338 500,120 130,118"`).
pub fn parse_corners(text: &str) -> std::result::Result<Vec<[f64; 2]>, String> {
    text.split(|c: char| c.is_whitespace() || c == ';')
        .filter(|s| !s.is_empty())
        .map(|pair| {
            let v: Vec<f64> = pair
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<std::result::Result<_, _>>()
                .map_err(|_| format!("corner `{pair}`: expected two pixel numbers u,v"))?;
            match v[..] {
                [u, v] if u.is_finite() && v.is_finite() => Ok([u, v]),
                _ => Err(format!("corner `{pair}`: expected two pixel numbers u,v")),
            }
        })
        .collect()
}

/// Reads corners from a file: JSON (`[[u, v], …]` or `{"corners": [[u, v], …]}`) or CSV (one
/// `u,v` per line; a header line and `#` comments are skipped).
pub fn load_corners(path: &Path) -> Result<Vec<[f64; 2]>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        || matches!(text.trim_start().chars().next(), Some('[' | '{'));
    if is_json {
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| Error::parse(path, e.line(), format!("not valid JSON: {e}")))?;
        let list = v.get("corners").unwrap_or(&v);
        let arr = list
            .as_array()
            .ok_or_else(|| Error::invalid(path, "expected a list of [u, v] corners"))?;
        return arr
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let p = c.as_array().and_then(|a| {
                    (a.len() == 2)
                        .then(|| Some([a[0].as_f64()?, a[1].as_f64()?]))
                        .flatten()
                });
                p.filter(|p| p.iter().all(|x| x.is_finite()))
                    .ok_or_else(|| {
                        Error::invalid(path, format!("corner {i}: expected [u, v] in pixels"))
                    })
            })
            .collect();
    }
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = t.split(',').map(str::trim).collect();
        let nums: Option<Vec<f64>> = fields.iter().map(|f| f.parse::<f64>().ok()).collect();
        match nums {
            Some(v) if v.len() == 2 && v.iter().all(|x| x.is_finite()) => out.push([v[0], v[1]]),
            None if out.is_empty() && fields.iter().all(|f| f.parse::<f64>().is_err()) => {} // header
            _ => {
                return Err(Error::parse(
                    path,
                    i + 1,
                    format!("expected `u,v` in pixels, got `{t}`"),
                ));
            }
        }
    }
    Ok(out)
}

/// How high the acting shoulder is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ShoulderHeight {
    /// Metres above the table surface, measured.
    AboveTable(f64),
    /// Estimated from the person's height (metres) with Drillis & Contini's segment proportions:
    /// shoulder at 0.818 H standing; seated, the thigh is horizontal, which lowers it by the hip
    /// height minus the knee height ((0.530 − 0.285) H), giving 0.573 H above the floor.
    PersonHeight {
        /// The person's height, metres.
        height: f64,
        /// Standing (else seated) at the table.
        standing: bool,
    },
}

/// Everything [`calibrate`] needs.
#[derive(Clone, Debug)]
pub struct CalibrationInput {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The camera's intrinsics at this image size.
    pub intrinsics: Intrinsics,
    /// The table's corners in pixels: near-left, near-right, far-right, far-left (actor's view).
    pub corners: Vec<[f64; 2]>,
    /// The table's size: along its near edge and across it, metres.
    pub table_size: [f64; 2],
    /// The size of the region where the targets lie (the scene's table region), centred on the
    /// table; `None`: the whole table.
    pub region_size: Option<[f64; 2]>,
    /// Height of the table surface above the floor, metres.
    pub table_height: f64,
    /// The acting arm.
    pub side: Side,
    /// The acting shoulder's pixel in a frame where the arm rests.
    pub shoulder_px: [f64; 2],
    /// The acting shoulder's height.
    pub shoulder_height: ShoulderHeight,
    /// The largest corner reprojection error accepted, pixels.
    pub max_error_px: f64,
    /// Edge-image parameters written into the scene.
    pub edges: EdgeSettings,
}

/// A calibrated scene and how well it fits.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The scene (one camera, the table region, the actor).
    pub scene: Scene,
    /// Reprojection error of each corner, pixels.
    pub corner_errors_px: [f64; 4],
    /// Root mean square of the corner errors, pixels.
    pub rms_error_px: f64,
    /// Height of the acting shoulder above the table surface, metres.
    pub shoulder_above_table: f64,
    /// The table's corners in the world (near-left, near-right, far-right, far-left).
    pub table_corners: [Vector3<f64>; 4],
}

impl Calibration {
    /// The largest corner reprojection error, pixels.
    pub fn max_error_px(&self) -> f64 {
        self.corner_errors_px.iter().copied().fold(0.0, f64::max)
    }
}

fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn sub2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// `true` when segments ab and cd cross at an interior point.
fn segments_cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let d1 = cross2(sub2(b, a), sub2(c, a));
    let d2 = cross2(sub2(b, a), sub2(d, a));
    let d3 = cross2(sub2(d, c), sub2(a, c));
    let d4 = cross2(sub2(d, c), sub2(b, c));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// Checks that four image points form a convex, non-degenerate quadrilateral.
pub fn check_quadrilateral(c: &[[f64; 2]]) -> Result<()> {
    if c.len() != 4 {
        return Err(Error::Config(format!(
            "the table needs exactly 4 corners (near-left, near-right, far-right, far-left), got {}",
            c.len()
        )));
    }
    for i in 0..4 {
        for j in i + 1..4 {
            if (c[i][0] - c[j][0]).hypot(c[i][1] - c[j][1]) < 2.0 {
                return Err(Error::Config(format!(
                    "corners {} and {} are less than 2 px apart: {:?} and {:?}",
                    i + 1,
                    j + 1,
                    c[i],
                    c[j]
                )));
            }
        }
    }
    if segments_cross(c[0], c[1], c[2], c[3]) || segments_cross(c[1], c[2], c[3], c[0]) {
        return Err(Error::Config(
            "the corners form a self-crossing quadrilateral: give them in order around the table \
             (near-left, near-right, far-right, far-left as the actor sees them)"
                .into(),
        ));
    }
    let turns: Vec<f64> = (0..4)
        .map(|i| {
            cross2(
                sub2(c[(i + 1) % 4], c[i]),
                sub2(c[(i + 2) % 4], c[(i + 1) % 4]),
            )
        })
        .collect();
    if !(turns.iter().all(|&t| t > 0.0) || turns.iter().all(|&t| t < 0.0)) {
        return Err(Error::Config(
            "the corners form a concave quadrilateral; a rectangle seen by a camera is convex \
             (is a corner misplaced?)"
                .into(),
        ));
    }
    let area = 0.5 * (cross2(sub2(c[2], c[0]), sub2(c[3], c[1]))).abs();
    if area < 100.0 {
        return Err(Error::Config(format!(
            "the table covers {area:.0} px² of the image, too little to calibrate from"
        )));
    }
    Ok(())
}

fn residuals(cam: &SceneCamera, world: &[Vector3<f64>], px: &[[f64; 2]], out: &mut [f64]) -> bool {
    for (i, (x, p)) in world.iter().zip(px).enumerate() {
        let Some((u, v)) = cam.project(x) else {
            return false;
        };
        out[2 * i] = u - p[0];
        out[2 * i + 1] = v - p[1];
    }
    true
}

/// Refines a pose by Levenberg–Marquardt on the pixel residuals (numerical Jacobian; the
/// rotation is updated on the left by a rotation vector).
fn refine(
    intr: &Intrinsics,
    size: (u32, u32),
    world: &[Vector3<f64>],
    px: &[[f64; 2]],
    mut r: Matrix3<f64>,
    mut t: Vector3<f64>,
) -> (Matrix3<f64>, Vector3<f64>) {
    let n = 2 * world.len();
    let cost = |r: &Matrix3<f64>, t: &Vector3<f64>, buf: &mut Vec<f64>| -> f64 {
        buf.resize(n, 0.0);
        let cam = intr.camera(size.0, size.1, *r, *t);
        if residuals(&cam, world, px, buf) {
            buf.iter().map(|e| e * e).sum()
        } else {
            f64::INFINITY
        }
    };
    let apply = |r: &Matrix3<f64>, t: &Vector3<f64>, d: &Vector6<f64>| {
        let dr = Rotation3::new(Vector3::new(d[0], d[1], d[2]));
        (dr.matrix() * r, t + Vector3::new(d[3], d[4], d[5]))
    };
    let mut buf = Vec::new();
    let mut res = Vec::new();
    let mut c0 = cost(&r, &t, &mut res);
    if !c0.is_finite() {
        return (r, t);
    }
    let mut lambda = 1e-3;
    for _ in 0..100 {
        let mut jac = vec![Vector6::zeros(); n];
        for k in 0..6 {
            let h = if k < 3 {
                1e-7
            } else {
                1e-7 * t.norm().max(1.0)
            };
            let mut d = Vector6::zeros();
            d[k] = h;
            let (rp, tp) = apply(&r, &t, &d);
            let cp = cost(&rp, &tp, &mut buf);
            if !cp.is_finite() {
                return (r, t);
            }
            for i in 0..n {
                jac[i][k] = (buf[i] - res[i]) / h;
            }
        }
        let mut jtj = Matrix6::zeros();
        let mut jtr = Vector6::zeros();
        for i in 0..n {
            jtj += jac[i] * jac[i].transpose();
            jtr += jac[i] * res[i];
        }
        let mut improved = false;
        for _ in 0..10 {
            let mut a = jtj;
            for k in 0..6 {
                a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(d) = a.lu().solve(&(-jtr)) else {
                lambda *= 10.0;
                continue;
            };
            let (rn, tn) = apply(&r, &t, &d);
            let cn = cost(&rn, &tn, &mut buf);
            if cn < c0 {
                let small = d.norm() < 1e-12 || (c0 - cn) < 1e-14 * c0.max(1e-30);
                r = rn;
                t = tn;
                c0 = cn;
                std::mem::swap(&mut res, &mut buf);
                lambda = (lambda / 10.0).max(1e-12);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    // Re-orthonormalise the accumulated rotation.
    let r = Rotation3::from_matrix(&r).into_inner();
    (r, t)
}

/// Solves the camera pose (R_cw, t_cw) from world points on a plane and their pixels: SQPnP on
/// the undistorted points, refined on the distorted pixel residuals.
pub fn solve_pose(
    intr: &Intrinsics,
    size: (u32, u32),
    world: &[Vector3<f64>],
    px: &[[f64; 2]],
) -> Result<(Matrix3<f64>, Vector3<f64>)> {
    let undistorter = actrack_render::Camera {
        width: size.0,
        height: size.1,
        fx: intr.fx,
        fy: intr.fy,
        cx: intr.cx,
        cy: intr.cy,
        distortion: intr.distortion,
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };
    let p2: Vec<(f64, f64)> = px
        .iter()
        .map(|p| {
            undistorter
                .undistort((p[0] - intr.cx) / intr.fx, (p[1] - intr.cy) / intr.fy)
                .ok_or_else(|| {
                    Error::Config(format!(
                        "corner {p:?} lies outside the distortion model's valid field"
                    ))
                })
        })
        .collect::<Result<_>>()?;
    let p3: Vec<(f64, f64, f64)> = world.iter().map(|x| (x.x, x.y, x.z)).collect();
    let ((rx, ry, rz), (tx, ty, tz)) = sqpnp_simple::sqpnp_solve(&p3, &p2).ok_or_else(|| {
        Error::Config(
            "no camera pose puts the table in front of the camera: check the corners' order and \
             the intrinsics"
                .into(),
        )
    })?;
    let r0 = Rotation3::new(Vector3::new(rx, ry, rz)).into_inner();
    let t0 = Vector3::new(tx, ty, tz);
    if !(r0.iter().chain(t0.iter()).all(|v| v.is_finite())) {
        return Err(Error::Config("the PnP solution is not finite".into()));
    }
    Ok(refine(intr, size, world, px, r0, t0))
}

/// Calibrates a scene: camera pose from the corners, the actor from the shoulder.
pub fn calibrate(input: &CalibrationInput) -> Result<Calibration> {
    let [sx, sy] = input.table_size;
    if !(sx.is_finite() && sy.is_finite() && sx > 0.05 && sy > 0.05 && sx < 20.0 && sy < 20.0) {
        return Err(Error::Config(format!(
            "table size must be two lengths in metres between 0.05 and 20, got {sx} × {sy}"
        )));
    }
    if !(input.table_height.is_finite() && (0.0..5.0).contains(&input.table_height)) {
        return Err(Error::Config(format!(
            "table height must be in [0, 5) m, got {}",
            input.table_height
        )));
    }
    if !(input.max_error_px.is_finite() && input.max_error_px > 0.0) {
        return Err(Error::Config("the error threshold must be positive".into()));
    }
    let [rx, ry] = input.region_size.unwrap_or(input.table_size);
    if !(rx.is_finite() && ry.is_finite() && rx > 0.0 && ry > 0.0 && rx <= sx && ry <= sy) {
        return Err(Error::Config(format!(
            "the target region {rx} × {ry} m must be positive and fit on the {sx} × {sy} m table"
        )));
    }
    check_quadrilateral(&input.corners)?;
    let placement = Placement {
        origin: Vector3::new(0.0, 0.0, input.table_height),
        yaw: 0.0,
    };
    let world = SceneTable {
        placement,
        half_extents: [sx / 2.0, sy / 2.0],
    }
    .corners();
    let table = SceneTable {
        placement,
        half_extents: [rx / 2.0, ry / 2.0],
    };
    let size = (input.width, input.height);
    let (r, t) = solve_pose(&input.intrinsics, size, &world, &input.corners)?;
    let camera = input.intrinsics.camera(input.width, input.height, r, t);
    // The table must be in front of the camera and seen from above.
    for (i, x) in world.iter().enumerate() {
        if camera.model.to_camera(x).z <= 0.01 {
            return Err(Error::Config(format!(
                "corner {} of the table ends up behind the camera: check the corners and the \
                 intrinsics",
                i + 1
            )));
        }
    }
    if camera.centre().z <= input.table_height {
        return Err(Error::Config(
            "the solution sees the table from below: the corners are probably mirrored; give \
             them near-left, near-right, far-right, far-left as the actor sees them"
                .into(),
        ));
    }
    let mut res = [0.0; 8];
    if !residuals(&camera, &world, &input.corners, &mut res) {
        return Err(Error::Config("a corner does not project".into()));
    }
    let errs: [f64; 4] = std::array::from_fn(|i| res[2 * i].hypot(res[2 * i + 1]));
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / 4.0).sqrt();
    let max = errs.iter().copied().fold(0.0, f64::max);
    if max.is_nan() || max > input.max_error_px {
        return Err(Error::Config(format!(
            "corner reprojection error {max:.1} px (rms {rms:.1} px) is above the threshold \
             {:.1} px: check the corners, the table size and the intrinsics",
            input.max_error_px
        )));
    }
    // The shoulder: on its pixel's ray at its height.
    let above = match input.shoulder_height {
        ShoulderHeight::AboveTable(h) => h,
        ShoulderHeight::PersonHeight { height, standing } => {
            if !(height.is_finite() && (0.5..2.5).contains(&height)) {
                return Err(Error::Config(format!(
                    "person height must be in metres between 0.5 and 2.5, got {height}"
                )));
            }
            (if standing { 0.818 } else { 0.573 }) * height - input.table_height
        }
    };
    if !(above.is_finite() && (0.0..1.5).contains(&above)) {
        return Err(Error::Config(format!(
            "the shoulder must be between 0 and 1.5 m above the table, got {above:.2} m (check \
             the shoulder height or the person's height and the table height)"
        )));
    }
    let render = camera.model.clone();
    let [su, sv] = input.shoulder_px;
    let z_shoulder = input.table_height + above;
    let ray = render
        .back_project(su, sv, 1.0)
        .map(|p| p - camera.centre())
        .ok_or_else(|| Error::Config(format!("shoulder pixel ({su}, {sv}) does not undistort")))?;
    let c = camera.centre();
    let s = (z_shoulder - c.z) / ray.z;
    if !(s.is_finite() && s > 0.0) {
        return Err(Error::Config(format!(
            "the shoulder's pixel ray does not reach {above:.2} m above the table in front of the \
             camera (the camera is at {:.2} m above the table)",
            c.z - input.table_height
        )));
    }
    let origin = c + ray * s;
    if origin.y > -sy / 2.0 + 0.05 {
        return Err(Error::Config(format!(
            "the shoulder lands {:.2} m across the table from its near edge: the actor sits at the \
             near edge; check the corners' order (near-left first) and the shoulder pixel",
            origin.y + sy / 2.0
        )));
    }
    let scene = Scene {
        cameras: vec![camera],
        table,
        actor: Placement { origin, yaw: 0.0 },
        side: input.side,
        arm: ArmSettings::default(),
        edges: input.edges.clone(),
    };
    Ok(Calibration {
        scene,
        corner_errors_px: errs,
        rms_error_px: rms,
        shoulder_above_table: above,
        table_corners: world,
    })
}

fn put(img: &mut RgbImage, u: f64, v: f64, c: [u8; 3]) {
    let (ui, vi) = (u.round(), v.round());
    if ui >= 0.0 && vi >= 0.0 && ui < f64::from(img.width()) && vi < f64::from(img.height()) {
        img.put_pixel(ui as u32, vi as u32, Rgb(c));
    }
}

/// Draws the world segment a–b, projected point by point (so distortion bends it).
fn world_line(
    img: &mut RgbImage,
    cam: &SceneCamera,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: [u8; 3],
) {
    let (Some(pa), Some(pb)) = (cam.project(a), cam.project(b)) else {
        return;
    };
    let n = ((pa.0 - pb.0).hypot(pa.1 - pb.1) * 2.0).clamp(2.0, 20_000.0) as usize;
    for i in 0..=n {
        let s = i as f64 / n as f64;
        if let Some((u, v)) = cam.project(&(a + (b - a) * s)) {
            for (du, dv) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] {
                put(img, u + du, v + dv, c);
            }
        }
    }
}

fn cross(img: &mut RgbImage, u: f64, v: f64, c: [u8; 3]) {
    for d in -5..=5 {
        let d = f64::from(d);
        put(img, u + d, v + d, c);
        put(img, u + d, v - d, c);
    }
}

fn ring(img: &mut RgbImage, u: f64, v: f64, r: f64, c: [u8; 3]) {
    for i in 0..64 {
        let a = f64::from(i) / 64.0 * std::f64::consts::TAU;
        put(img, u + r * a.cos(), v + r * a.sin(), c);
    }
}

/// Draws the calibration on a frame: the table outline (yellow), the target region (white, when
/// smaller than the table), the world axes at the table's centre (x red, y green, z blue, 20 cm),
/// the given corners (white crosses) and their reprojections (cyan rings), the shoulder (magenta
/// ring) and the contour of the arm in
/// `rest_pose_actor` (actor frame, metres) with `lengths` (L1, L2), in orange.
pub fn draw_preview(
    img: &mut RgbImage,
    cal: &Calibration,
    corners: &[[f64; 2]],
    rest_pose_actor: &[f64; 9],
    lengths: [f64; 2],
) {
    let scene = &cal.scene;
    let cam = &scene.cameras[0];
    let k = cal.table_corners;
    let region = scene.table.corners();
    for i in 0..4 {
        world_line(img, cam, &k[i], &k[(i + 1) % 4], [255, 230, 0]);
        if region != k {
            world_line(img, cam, &region[i], &region[(i + 1) % 4], [255, 255, 255]);
        }
    }
    let o = scene.table.placement.origin;
    for (axis, c) in [
        (Vector3::x(), [255, 40, 40]),
        (Vector3::y(), [40, 220, 40]),
        (Vector3::z(), [60, 120, 255]),
    ] {
        world_line(img, cam, &o, &(o + axis * 0.2), c);
    }
    let mut pose = scene.pose_to_world(rest_pose_actor);
    let render_cam = cam.model.clone();
    let geometry = crate::scene::render_arm(scene, lengths);
    actrack_render::correct_arm(&geometry, &mut pose, None);
    let contour = actrack_render::contour_points(
        &render_cam,
        &geometry,
        &pose,
        actrack_render::ContourMethod::Analytic,
    );
    for p in contour {
        put(img, p[0], p[1], [255, 120, 0]);
        put(img, p[0] + 1.0, p[1], [255, 120, 0]);
    }
    for c in corners {
        cross(img, c[0], c[1], [255, 255, 255]);
    }
    for x in &k {
        if let Some((u, v)) = cam.project(x) {
            ring(img, u, v, 4.0, [0, 230, 230]);
        }
    }
    if let Some((u, v)) = cam.project(&scene.actor.origin) {
        ring(img, u, v, 6.0, [255, 0, 255]);
    }
}

/// A rest pose in the actor frame for the preview: the first action's first state's mean at the
/// centre of its training targets, or, without a model, the hand resting on the table in front
/// of the shoulder.
pub fn rest_pose(model: Option<&crate::ActionModel>, shoulder_above_table: f64) -> [f64; 9] {
    if let Some(a) = model.and_then(|m| m.actions.first())
        && a.phmm.dim() == 9
        && a.phmm.theta_dim() == 2
    {
        let (centre, _) = a.phmm.theta_normalisation();
        let m = a.phmm.mean(0, centre);
        let mut out = [0.0; 9];
        for (o, v) in out.iter_mut().zip(m.iter()) {
            *o = *v;
        }
        if out.iter().all(|v| v.is_finite()) {
            return out;
        }
    }
    let z = -shoulder_above_table;
    [0.0, 0.0, 0.0, 0.05, 0.05, z * 0.6, 0.2, 0.2, z + 0.02]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadrilateral_checks() {
        let sq = [[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]];
        assert!(check_quadrilateral(&sq).is_ok());
        assert!(check_quadrilateral(&sq[..3]).is_err());
        let bow = [[0.0, 0.0], [100.0, 100.0], [100.0, 0.0], [0.0, 100.0]];
        let e = check_quadrilateral(&bow).unwrap_err().to_string();
        assert!(e.contains("self-crossing"), "{e}");
        let concave = [[0.0, 0.0], [100.0, 0.0], [30.0, 30.0], [0.0, 100.0]];
        let e = check_quadrilateral(&concave).unwrap_err().to_string();
        assert!(e.contains("concave"), "{e}");
    }

    #[test]
    fn corners_parse() {
        assert_eq!(
            parse_corners("1,2 3.5,4;5,6\n7,8").unwrap(),
            vec![[1.0, 2.0], [3.5, 4.0], [5.0, 6.0], [7.0, 8.0]]
        );
        assert!(parse_corners("1,2 3").is_err());
    }

    #[test]
    #[allow(clippy::float_cmp)] // the numbers are parsed from exact decimal text
    fn opencv_yaml_and_json_intrinsics() {
        let dir = tempfile::tempdir().unwrap();
        let y = dir.path().join("cam.yml");
        std::fs::write(
            &y,
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 600., 0., 320.,\n       0., 610., 240., 0., 0., 1. ]\ndistortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ -0.1, 0.01, 0.001, -0.002, 0. ]\n",
        )
        .unwrap();
        let i = Intrinsics::load(&y).unwrap();
        assert_eq!((i.fx, i.fy, i.cx, i.cy), (600.0, 610.0, 320.0, 240.0));
        assert_eq!(i.distortion, [-0.1, 0.01, 0.001, -0.002, 0.0]);
        assert_eq!(i.size, Some((640, 480)));
        let half = i.for_size(320, 240).unwrap();
        assert!((half.fx - 300.0).abs() < 1e-12 && (half.cx - 159.75).abs() < 1e-12);
        assert!(i.for_size(320, 320).is_err());
        let j = dir.path().join("cam.json");
        std::fs::write(
            &j,
            r#"{"camera_matrix": [[500, 0, 160], [0, 500, 120], [0, 0, 1]], "dist_coeffs": [0.1, 0, 0, 0]}"#,
        )
        .unwrap();
        let i = Intrinsics::load(&j).unwrap();
        assert_eq!(
            (i.fx, i.cx, i.distortion[0], i.size),
            (500.0, 160.0, 0.1, None)
        );
    }

    #[test]
    fn left_arm_scene_mirrors_the_actor_frame() {
        let right = crate::scene::default_scene(320, 240);
        let left = Scene {
            side: Side::Left,
            ..right.clone()
        };
        let pose = [0.0, 0.0, 0.0, 0.1, 0.05, -0.25, 0.3, 0.35, -0.3];
        let (wr, wl) = (right.pose_to_world(&pose), left.pose_to_world(&pose));
        for j in 0..3 {
            // The actor's heading is 0: world x about the shoulder is mirrored, y and z agree.
            let o = right.actor.origin;
            assert!((wr[3 * j] - o.x + (wl[3 * j] - o.x)).abs() < 1e-12);
            assert!((wr[3 * j + 1] - wl[3 * j + 1]).abs() < 1e-12);
            assert!((wr[3 * j + 2] - wl[3 * j + 2]).abs() < 1e-12);
        }
        let back = left.pose_to_actor(&wl);
        assert!(back.iter().zip(&pose).all(|(a, b)| (a - b).abs() < 1e-12));
        let t = left.theta_to_world([0.1, 0.4]);
        assert!((t.x - right.actor.origin.x + 0.1).abs() < 1e-12);
        let (cl, hl) = left.theta_region();
        let (cr, hr) = right.theta_region();
        assert!((cl[0] + cr[0]).abs() < 1e-12 && (cl[1] - cr[1]).abs() < 1e-12);
        assert!((hl[0] - hr[0]).abs() < 1e-12 && (hl[1] - hr[1]).abs() < 1e-12);
    }
}
