//! The contour likelihood of a batch of particles on the GPU (feature `gpu`, wgpu compute
//! shaders), with the analytic contour of SPEC §4.2 and the multi-view sum of Eq. 4.
//!
//! # How the work is split
//!
//! * CPU, per particle and view (f64): the projection of the three arm parts
//!   (pinhole + Brown) into the analytic sampler's own prepared parts (degenerate capsules
//!   become discs, tangent angles; bounding-box rejection) and the number
//!   of samples on each line and arc of every outline. These are the discrete decisions of the
//!   sampler, so they are taken exactly as [`crate::LikelihoodModel`] takes them.
//! * GPU, one workgroup of 64 threads per (particle, view): the sample points (lines by
//!   interpolation, arcs by an f32 sine/cosine accurate to ~1e-7), the "not more than half a
//!   pixel inside another part" test, the rounding to a pixel, the image bounds, and the sum of
//!   `(1 − G)²` in exact 64-bit fixed point (two u32 words, 2⁻²⁴ per unit).
//! * CPU: `ε̄_v = sum / |C_v|` (1 when `|C_v| = 0`) and `log P = −Σ_v ε̄_v / (2γ²)`.
//!
//! # Agreement with the CPU
//!
//! The GPU computes sample positions in f32 relative to an integer anchor, so every position
//! is within ~1e-5 px of the f64 position of the CPU sampler. A sample whose discrete
//! decisions (rounded pixel, image bounds, inside another part) lie within a bound of that
//! error of flipping is *ambiguous*; the GPU flags its (particle, view) and the CPU scores that
//! view exactly. Every other view counts exactly the same pixels as the CPU, so the scores
//! agree to the fixed-point and f32 rounding of `(1 − G)²` (~1e-6 in log-likelihood). The
//! share of views rescored on the CPU is [`GpuLikelihood::last_fallbacks`] (a few percent for
//! arms 50–150 px across).
//!
//! Buffers live as long as the [`GpuLikelihood`] and grow only when a batch is larger than any
//! before; the edge images are uploaded when they differ from the last ones uploaded (once per
//! frame and view).

use std::sync::{Arc, Mutex, mpsc};

use bytemuck::{Pod, Zeroable};
use nalgebra::Vector2;

use crate::contour::{INSIDE_TOL, OutlineSink, Prepared, project_prepared};
use crate::{
    ArmGeometry, Camera, ContourMethod, EdgeImage, LikelihoodModel, RenderError, RenderScratch,
};

/// Spacing Δ of analytic samples, pixels (the CPU default).
const SPACING: f64 = 2.0;
/// Pieces (lines and arcs) per (particle, view): three parts of at most four pieces.
const PIECES_PER_JOB: usize = 12;
/// Parts per (particle, view).
const PARTS_PER_JOB: usize = 3;
/// Largest number of workgroups along one dispatch dimension (WebGPU minimum limit).
const MAX_GROUPS_X: u32 = 65_535;
/// Fixed-point scale of the `(1 − G)²` sums (must match the shader).
const FIXED_SCALE: f64 = 16_777_216.0;

/// What can go wrong on the GPU path. Callers usually fall back to the CPU likelihood.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpuError {
    /// No GPU adapter (no driver, or a headless machine without a software rasteriser such as
    /// Mesa lavapipe).
    #[error("no GPU adapter found: {0}")]
    NoAdapter(String),
    /// The adapter exists but cannot run the kernel (no compute shaders, too few storage
    /// buffers, device request failed, shader rejected, device lost, …).
    #[error("GPU unusable: {0}")]
    Device(String),
    /// A batch needs a buffer larger than the device allows.
    #[error("batch too large for the GPU: {0}")]
    TooLarge(String),
    /// Invalid model parameters or inputs (cameras, geometry, γ, edge images, output length).
    #[error(transparent)]
    Render(#[from] RenderError),
}

/// One line or arc of a part's outline, relative to an integer pixel anchor.
///
/// Line: `x_k = anchor + base + u·(k/n)`. Arc: `x_k = anchor + base + u·cos(kθ) + w·sin(kθ)`
/// with θ = `dt_hi + dt_lo`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
struct GpuPiece {
    /// kind (1 line, 2 arc), index of its part in the job, number of samples n, unused.
    head: [u32; 4],
    anchor: [i32; 2],
    base: [f32; 2],
    u: [f32; 2],
    w: [f32; 2],
    dt_hi: f32,
    dt_lo: f32,
    /// Positions are within this many pixels of the f64 positions.
    tol: f32,
    _pad: f32,
}

/// A part for the inside test, relative to an integer anchor.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
struct GpuPart {
    /// kind (0 never inside, 1 disc, 2 capsule, 3 ellipse), cap flags (bit 0: disc at c0 can
    /// contain points, bit 1: disc at c1), unused ×2.
    head: [u32; 4],
    anchor: [i32; 2],
    /// Disc / capsule start / ellipse centre, relative to the anchor.
    c0: [f32; 2],
    /// Capsule end minus start.
    c1: [f32; 2],
    /// Capsule direction, or the ellipse major axis direction.
    d: [f32; 2],
    /// Capsule normal, or the ellipse minor axis direction.
    n: [f32; 2],
    /// Disc: r, capsule: r0, ellipse: a.
    r0: f32,
    /// Capsule: r1, ellipse: b.
    r1: f32,
    /// Capsule: length, ellipse: 1 − INSIDE_TOL / b.
    len: f32,
    sin_a: f32,
    cos_a: f32,
    /// Magnitude of the part's coordinates (pixels), for the error bound.
    scale: f32,
    _pad: [f32; 4],
}

// The WGSL layouts of `Piece` and `Part` (16-byte aligned structs).
const _: () = assert!(size_of::<GpuPiece>() == 64 && size_of::<GpuPart>() == 96);

impl Prepared {
    /// The part for the inside test.
    fn gpu_part(&self) -> GpuPart {
        let mut g = GpuPart::default();
        match *self {
            Self::Circle { c, r } => {
                let (anchor, c0) = anchored(c);
                g.head = [u32::from(r > INSIDE_TOL), 0, 0, 0];
                g.anchor = anchor;
                g.c0 = c0;
                g.r0 = r as f32;
                g.scale = r as f32;
            }
            Self::Capsule {
                c0,
                c1,
                r0,
                r1,
                len,
                d,
                n,
                sin_a,
                cos_a,
            } => {
                let (anchor, base) = anchored(c0);
                let caps = u32::from(r0 > INSIDE_TOL) | (u32::from(r1 > INSIDE_TOL) << 1);
                g.head = [2, caps, 0, 0];
                g.anchor = anchor;
                g.c0 = base;
                g.c1 = f32x2(c1 - c0);
                g.d = f32x2(d);
                g.n = f32x2(n);
                g.r0 = r0 as f32;
                g.r1 = r1 as f32;
                g.len = len as f32;
                g.sin_a = sin_a as f32;
                g.cos_a = cos_a as f32;
                g.scale = (len + r0 + r1) as f32;
            }
            Self::Ellipse { c, a, b, ea, eb } => {
                let (anchor, base) = anchored(c);
                g.head = [if b > INSIDE_TOL { 3 } else { 0 }, 0, 0, 0];
                g.anchor = anchor;
                g.c0 = base;
                g.d = f32x2(ea);
                g.n = f32x2(eb);
                g.r0 = a as f32;
                g.r1 = b as f32;
                g.len = (1.0 - INSIDE_TOL / b) as f32;
                g.scale = a as f32;
            }
        }
        g
    }

    /// Appends the pieces of the outline: the CPU sampler's ([`Prepared::sample_outline`]), in
    /// its order and with its sample counts.
    fn pieces(&self, part: u32, step: f64, out: &mut Vec<GpuPiece>) {
        self.sample_outline(step, &mut PieceSink { part, out });
    }
}

/// Collects a part's outline as GPU pieces.
struct PieceSink<'a> {
    part: u32,
    out: &'a mut Vec<GpuPiece>,
}

impl OutlineSink for PieceSink<'_> {
    fn line(&mut self, p: Vector2<f64>, q: Vector2<f64>, n: usize) {
        self.out.push(line_piece(self.part, n, p, q));
    }
    fn trig(
        &mut self,
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
        _circle: bool,
    ) {
        self.out.push(arc_piece(self.part, n, c, u, w, theta));
    }
}

fn f32x2(v: Vector2<f64>) -> [f32; 2] {
    [v.x as f32, v.y as f32]
}

/// An integer anchor near `x` (its floor) and `x` relative to it, in [0, 1)².
fn anchored(x: Vector2<f64>) -> ([i32; 2], [f32; 2]) {
    let (fx, fy) = (x.x.floor(), x.y.floor());
    // |x| < 1e6 for every projected part (the projection rejects larger coordinates).
    (
        [fx as i32, fy as i32],
        [(x.x - fx) as f32, (x.y - fy) as f32],
    )
}

/// Error bound (pixels) of GPU positions built from vectors of total length `magnitude`.
///
/// Worst case per coordinate of an arc of radius r (|u| = |w| = r, magnitude ≈ 2r): u and w
/// rounded to f32 (r·6e-8 each), cos/sin within 2e-7, two products and two sums rounded
/// (r·1.2e-7 each): ≈ r·7e-7 + 1e-7. Lines: k/n within 2.5 ulp (Vulkan), so ≈ |u|·3e-7.
/// The bound below is about twice that; measured errors are more than 100× smaller (the
/// tests pass with the bound divided by 100).
fn position_tol(magnitude: f64) -> f32 {
    (2e-6 + 6e-7 * magnitude) as f32
}

fn line_piece(part: u32, n: usize, a: Vector2<f64>, b: Vector2<f64>) -> GpuPiece {
    let (anchor, base) = anchored(a);
    let u = b - a;
    GpuPiece {
        head: [1, part, n as u32, 0],
        anchor,
        base,
        u: f32x2(u),
        tol: position_tol(u.norm() + 1.0),
        ..GpuPiece::default()
    }
}

fn arc_piece(
    part: u32,
    n: usize,
    c: Vector2<f64>,
    u: Vector2<f64>,
    w: Vector2<f64>,
    dt: f64,
) -> GpuPiece {
    let (anchor, base) = anchored(c);
    // dt = dt_hi + dt_lo with dt_hi of 11 significant bits, so k·dt_hi is exact in f32 for
    // k < 2¹³ (arcs have at most 4096 samples).
    let dt_hi = f32::from_bits((dt as f32).to_bits() & 0xFFFF_E000);
    let dt_lo = (dt - f64::from(dt_hi)) as f32;
    GpuPiece {
        head: [2, part, n as u32, 0],
        anchor,
        base,
        u: f32x2(u),
        w: f32x2(w),
        dt_hi,
        dt_lo,
        tol: position_tol(u.norm() + w.norm() + 1.0),
        _pad: 0.0,
    }
}

/// The kernel. One workgroup per job (particle × view); threads stride over the samples of
/// each piece; sums are exact in fixed point (see the module docs).
const SHADER: &str = r"
struct Piece {
    head: vec4<u32>,
    anchor: vec2<i32>,
    base: vec2<f32>,
    u: vec2<f32>,
    w: vec2<f32>,
    dt_hi: f32,
    dt_lo: f32,
    tol: f32,
    pad: f32,
}

struct Part {
    head: vec4<u32>,
    anchor: vec2<i32>,
    c0: vec2<f32>,
    c1: vec2<f32>,
    d: vec2<f32>,
    n: vec2<f32>,
    r0: f32,
    r1: f32,
    len: f32,
    sin_a: f32,
    cos_a: f32,
    scale: f32,
    pad: vec4<f32>,
}

// x: number of jobs, y: workgroups along x.
@group(0) @binding(0) var<uniform> params: vec4<u32>;
@group(0) @binding(1) var<storage, read> edges: array<f32>;
// Per job: edge offset, width, height, pieces | parts << 16.
@group(0) @binding(2) var<storage, read> jobs: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> pieces: array<Piece>;
@group(0) @binding(4) var<storage, read> parts: array<Part>;
// Per job: sum low word, sum high word, count, ambiguous.
@group(0) @binding(5) var<storage, read_write> results: array<vec4<u32>>;

var<workgroup> wg_lo: atomic<u32>;
var<workgroup> wg_hi: atomic<u32>;
var<workgroup> wg_count: atomic<u32>;
var<workgroup> wg_amb: atomic<u32>;

const INSIDE_TOL: f32 = 0.5;
const FIXED_SCALE: f32 = 16777216.0;
const PIECES_PER_JOB: u32 = 12u;
const PARTS_PER_JOB: u32 = 3u;
const BIG: f32 = 1.0e30;

// (cos θ, sin θ) for θ = k·(dt_hi + dt_lo), θ ∈ [0, 2π], absolute error ~1e-7: exact k·dt_hi,
// Cody–Waite reduction by π/2, Cephes minimax polynomials on [−π/4, π/4].
fn cos_sin(k: u32, dt_hi: f32, dt_lo: f32) -> vec2<f32> {
    let kf = f32(k);
    let p_hi = kf * dt_hi;
    let p_lo = kf * dt_lo;
    let q = floor((p_hi + p_lo) * 0.63661977 + 0.5);
    let x = ((p_hi - q * 1.5703125) - q * 4.8375129699707031e-4) - q * 7.5497899548918821e-8
        + p_lo;
    let z = x * x;
    let s = ((-1.9515295891e-4 * z + 8.3321608736e-3) * z - 1.6666654611e-1) * z * x + x;
    let c = ((2.443315711809948e-5 * z - 1.388731625493765e-3) * z + 4.166664568298827e-2)
        * z * z - 0.5 * z + 1.0;
    let quadrant = i32(q) & 3;
    var r = vec2<f32>(c, s);
    if quadrant == 1 {
        r = vec2<f32>(-s, c);
    } else if quadrant == 2 {
        r = vec2<f32>(-c, -s);
    } else if quadrant == 3 {
        r = vec2<f32>(s, -c);
    }
    return r;
}

// Signed margin (pixels, negative = more than INSIDE_TOL inside) of x relative to the part's
// anchor; BIG when the part cannot contain it.
fn inside_margin(p: Part, r: vec2<f32>) -> f32 {
    let kind = p.head.x;
    if kind == 1u {
        return length(r - p.c0) - (p.r0 - INSIDE_TOL);
    }
    if kind == 2u {
        let rel = r - p.c0;
        let s = dot(rel, p.d);
        if s < p.r0 * p.sin_a {
            if (p.head.y & 1u) != 0u {
                return length(rel) - (p.r0 - INSIDE_TOL);
            }
            return BIG;
        }
        if s > p.len + p.r1 * p.sin_a {
            if (p.head.y & 2u) != 0u {
                return length(rel - p.c1) - (p.r1 - INSIDE_TOL);
            }
            return BIG;
        }
        return s * p.sin_a + abs(dot(rel, p.n)) * p.cos_a - (p.r0 - INSIDE_TOL);
    }
    if kind == 3u {
        let rel = r - p.c0;
        let xa = dot(rel, p.d) / p.r0;
        let xb = dot(rel, p.n) / p.r1;
        return (sqrt(xa * xa + xb * xb) - p.len) * p.r1;
    }
    return BIG;
}

@compute @workgroup_size(64)
fn main(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if lid == 0u {
        atomicStore(&wg_lo, 0u);
        atomicStore(&wg_hi, 0u);
        atomicStore(&wg_count, 0u);
        atomicStore(&wg_amb, 0u);
    }
    workgroupBarrier();
    let j = wid.x + wid.y * params.y;
    let live = j < params.x;
    var lo = 0u;
    var hi = 0u;
    var count = 0u;
    var amb = 0u;
    if live {
        let job = jobs[j];
        let width = i32(job.y);
        let height = i32(job.z);
        let n_pieces = job.w & 0xFFFFu;
        let n_parts = job.w >> 16u;
        for (var pi = 0u; pi < n_pieces; pi++) {
            let pc = pieces[j * PIECES_PER_JOB + pi];
            let kind = pc.head.x;
            let own = pc.head.y;
            let n = pc.head.z;
            for (var k = lid; k < n; k += 64u) {
                var rel: vec2<f32>;
                if kind == 1u {
                    rel = pc.base + pc.u * (f32(k) / f32(n));
                } else {
                    let cs = cos_sin(k, pc.dt_hi, pc.dt_lo);
                    rel = pc.base + pc.u * cs.x + pc.w * cs.y;
                }
                let y = rel + vec2<f32>(0.5);
                let lo_px = pc.anchor + vec2<i32>(floor(y - vec2<f32>(pc.tol)));
                let hi_px = pc.anchor + vec2<i32>(floor(y + vec2<f32>(pc.tol)));
                // Every candidate pixel outside the image: not on C.
                if hi_px.x < 0 || hi_px.y < 0 || lo_px.x >= width || lo_px.y >= height {
                    continue;
                }
                var excluded = false;
                var unsure = false;
                for (var o = 0u; o < n_parts; o++) {
                    if o == own {
                        continue;
                    }
                    let p = parts[j * PARTS_PER_JOB + o];
                    let r = vec2<f32>(pc.anchor - p.anchor) + rel;
                    let m = inside_margin(p, r);
                    // Rounding of the part's parameters and of the margin's few
                    // operations (sqrt and division within 2.5 ulp), ≈ 16 ulp of the
                    // magnitudes involved.
                    let tol = pc.tol + 2.0e-6 + 6.0e-7 * (p.scale + length(r - p.c0));
                    if m < -tol {
                        excluded = true;
                    } else if m <= tol {
                        unsure = true;
                    }
                }
                if excluded {
                    continue;
                }
                if unsure || any(lo_px != hi_px) {
                    amb = 1u;
                    continue;
                }
                let g = edges[job.x + u32(lo_px.y * width + lo_px.x)];
                let e = 1.0 - g;
                let e2 = e * e;
                if !(e2 < 255.0) {
                    // Far outside [0, 1] (or NaN): leave it to the CPU.
                    amb = 1u;
                    continue;
                }
                let q = u32(e2 * FIXED_SCALE + 0.5);
                let next = lo + q;
                if next < lo {
                    hi += 1u;
                }
                lo = next;
                count += 1u;
            }
        }
        let old = atomicAdd(&wg_lo, lo);
        if old + lo < old {
            atomicAdd(&wg_hi, 1u);
        }
        atomicAdd(&wg_hi, hi);
        atomicAdd(&wg_count, count);
        atomicOr(&wg_amb, amb);
    }
    workgroupBarrier();
    if live && lid == 0u {
        results[j] = vec4<u32>(
            atomicLoad(&wg_lo),
            atomicLoad(&wg_hi),
            atomicLoad(&wg_count),
            atomicLoad(&wg_amb),
        );
    }
}
";

/// GPU buffers sized for `capacity` jobs, and the bind group over them.
struct Buffers {
    capacity: usize,
    jobs: wgpu::Buffer,
    pieces: wgpu::Buffer,
    parts: wgpu::Buffer,
    results: wgpu::Buffer,
    readback: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

/// Mutable state behind the lock: buffers, the edge images last uploaded, host staging.
struct State {
    edges: wgpu::Buffer,
    /// Offsets (in f32) of each view's edge image in `edges`.
    edge_offsets: Vec<u32>,
    uploaded: Vec<Vec<f32>>,
    buffers: Option<Buffers>,
    jobs: Vec<[u32; 4]>,
    pieces: Vec<GpuPiece>,
    parts: Vec<GpuPart>,
    results: Vec<[u32; 4]>,
    scratch: RenderScratch,
    fallbacks: usize,
}

/// The analytic contour likelihood of batches of poses on the GPU (see the module docs).
/// Same scores as [`LikelihoodModel`] with [`ContourMethod::Analytic`], nearest-pixel
/// sampling and Δ = 2 px.
pub struct GpuLikelihood {
    cpu: LikelihoodModel,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    errors: Arc<Mutex<Vec<String>>>,
    adapter: String,
    software: bool,
    max_buffer: u64,
    state: Mutex<State>,
}

impl std::fmt::Debug for GpuLikelihood {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuLikelihood")
            .field("adapter", &self.adapter)
            .field("views", &self.cpu.cameras().len())
            .finish_non_exhaustive()
    }
}

fn storage(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage: wgpu::BufferUsages::STORAGE | extra,
        mapped_at_creation: false,
    })
}

impl GpuLikelihood {
    /// Validates the model like [`LikelihoodModel::new`], then opens the first GPU adapter
    /// (honouring `WGPU_BACKEND` / `WGPU_ADAPTER_NAME`) and compiles the kernel. Returns
    /// [`GpuError::NoAdapter`] when there is none, so callers can fall back to the CPU.
    pub fn new(cameras: Vec<Camera>, geometry: ArmGeometry, gamma: f64) -> Result<Self, GpuError> {
        let cpu = LikelihoodModel::new(cameras, geometry, gamma, ContourMethod::Analytic)?;
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let name = format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type);
        if !adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        {
            return Err(GpuError::Device(format!("{name}: no compute shaders")));
        }
        let limits = adapter.limits();
        if limits.max_storage_buffers_per_shader_stage < 5 {
            return Err(GpuError::Device(format!(
                "{name}: {} storage buffers per stage, 5 needed",
                limits.max_storage_buffers_per_shader_stage
            )));
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("actrack-render gpu likelihood"),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(format!("{name}: {e}")))?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&errors);
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("contour likelihood"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("contour likelihood"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Device(format!("{name}: kernel rejected: {e}")));
        }
        let layout = pipeline.get_bind_group_layout(0);
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let max_buffer = limits
            .max_buffer_size
            .min(limits.max_storage_buffer_binding_size);
        let views = cpu.cameras().len();
        let mut edge_offsets = Vec::with_capacity(views);
        let mut total = 0u64;
        for c in cpu.cameras() {
            edge_offsets
                .push(u32::try_from(total).map_err(|_| GpuError::TooLarge("edge images".into()))?);
            total += u64::from(c.width) * u64::from(c.height);
        }
        if total * 4 > max_buffer {
            return Err(GpuError::TooLarge(format!(
                "edge images of {} MB, the device allows {} MB",
                (total * 4) >> 20,
                max_buffer >> 20
            )));
        }
        let edges = storage(&device, "edges", total * 4, wgpu::BufferUsages::COPY_DST);
        let state = State {
            edges,
            edge_offsets,
            uploaded: vec![Vec::new(); views],
            buffers: None,
            jobs: Vec::new(),
            pieces: Vec::new(),
            parts: Vec::new(),
            results: Vec::new(),
            scratch: RenderScratch::new(),
            fallbacks: 0,
        };
        let this = Self {
            cpu,
            device,
            queue,
            pipeline,
            layout,
            params,
            errors,
            adapter: name,
            software: info.device_type == wgpu::DeviceType::Cpu,
            max_buffer,
            state: Mutex::new(state),
        };
        this.check_errors()?;
        Ok(this)
    }

    /// The adapter in use: name, backend and device type (e.g. `llvmpipe (…) (Vulkan, Cpu)`).
    pub fn adapter_name(&self) -> &str {
        &self.adapter
    }

    /// Whether the adapter is a software rasteriser running on the CPU (Mesa lavapipe /
    /// llvmpipe, WARP, SwiftShader): correct, but slower than [`LikelihoodModel`].
    pub fn is_software(&self) -> bool {
        self.software
    }

    /// The CPU model with the same cameras, geometry and γ (analytic contours).
    pub fn cpu_model(&self) -> &LikelihoodModel {
        &self.cpu
    }

    /// How many (particle, view) pairs of the last batch were rescored on the CPU because a
    /// sample lay within the f32 error bound of a pixel or part boundary.
    pub fn last_fallbacks(&self) -> usize {
        self.state.lock().map_or(0, |s| s.fallbacks)
    }

    fn check_errors(&self) -> Result<(), GpuError> {
        let mut v = self
            .errors
            .lock()
            .map_err(|_| GpuError::Device("error sink poisoned".into()))?;
        if v.is_empty() {
            Ok(())
        } else {
            let msg = v.join("; ");
            v.clear();
            Err(GpuError::Device(msg))
        }
    }

    /// log P(I | x̃) of every pose into `out` (SPEC Eq. 3/4 with analytic contours): one edge
    /// image per camera, poses in the world frame (already corrected).
    pub fn log_likelihood_batch(
        &self,
        edges: &[EdgeImage],
        poses: &[[f64; 9]],
        out: &mut [f64],
    ) -> Result<(), GpuError> {
        self.cpu.check_edges(edges)?;
        if out.len() != poses.len() {
            return Err(RenderError::OutputLength {
                expected: poses.len(),
                got: out.len(),
            }
            .into());
        }
        let mut guard = self
            .state
            .lock()
            .map_err(|_| GpuError::Device("state poisoned by an earlier panic".into()))?;
        let st = &mut *guard;
        st.fallbacks = 0;
        if poses.is_empty() {
            return Ok(());
        }
        self.upload_edges(st, edges);
        self.build_jobs(st, poses);
        let n_jobs = st.jobs.len();
        if n_jobs == 0 {
            // Every pose is non-finite.
            st.results.clear();
            self.finish(st, edges, poses, out);
            return Ok(());
        }
        self.ensure_capacity(st, n_jobs)?;
        let Some(buf) = st.buffers.as_ref() else {
            return Err(GpuError::Device("buffers missing".into()));
        };
        self.queue
            .write_buffer(&buf.jobs, 0, bytemuck::cast_slice(&st.jobs));
        self.queue
            .write_buffer(&buf.pieces, 0, bytemuck::cast_slice(&st.pieces));
        self.queue
            .write_buffer(&buf.parts, 0, bytemuck::cast_slice(&st.parts));
        let jobs_u32 =
            u32::try_from(n_jobs).map_err(|_| GpuError::TooLarge(format!("{n_jobs} jobs")))?;
        let gx = jobs_u32.min(MAX_GROUPS_X);
        let gy = jobs_u32.div_ceil(gx);
        self.queue
            .write_buffer(&self.params, 0, bytemuck::cast_slice(&[jobs_u32, gx, 0, 0]));
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("contour likelihood"),
            });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("contour likelihood"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &buf.bind_group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        let bytes = (n_jobs * 16) as u64;
        enc.copy_buffer_to_buffer(&buf.results, 0, &buf.readback, 0, bytes);
        self.queue.submit([enc.finish()]);
        let (tx, rx) = mpsc::channel();
        buf.readback
            .map_async(wgpu::MapMode::Read, 0..bytes, move |r| {
                // The receiver waits below; a send error only means it gave up.
                let _ = tx.send(r);
            });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Device(format!("waiting for the GPU: {e}")))?;
        let mapped = rx
            .recv()
            .map_err(|_| GpuError::Device("the buffer map was dropped".into()))?;
        self.check_errors()?;
        mapped.map_err(|e| GpuError::Device(format!("reading results: {e}")))?;
        {
            let view = buf
                .readback
                .get_mapped_range(0..bytes)
                .map_err(|e| GpuError::Device(format!("reading results: {e}")))?;
            st.results.clear();
            st.results
                .extend_from_slice(bytemuck::cast_slice::<u8, [u32; 4]>(&view));
        }
        buf.readback.unmap();
        self.finish(st, edges, poses, out);
        Ok(())
    }

    /// Uploads each view's edge image unless it equals the one uploaded last.
    fn upload_edges(&self, st: &mut State, edges: &[EdgeImage]) {
        for (v, e) in edges.iter().enumerate() {
            if st.uploaded[v].as_slice() != e.data() {
                let offset = u64::from(st.edge_offsets[v]) * 4;
                self.queue
                    .write_buffer(&st.edges, offset, bytemuck::cast_slice(e.data()));
                st.uploaded[v].clear();
                st.uploaded[v].extend_from_slice(e.data());
            }
        }
    }

    /// One job per finite pose and view: projected parts (CPU, f64) and outline pieces.
    fn build_jobs(&self, st: &mut State, poses: &[[f64; 9]]) {
        st.jobs.clear();
        st.pieces.clear();
        st.parts.clear();
        let geometry = self.cpu.geometry();
        for pose in poses.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
            for (v, cam) in self.cpu.cameras().iter().enumerate() {
                let projected = project_prepared(cam, geometry, pose);
                let start = st.pieces.len();
                let (wf, hf) = (f64::from(cam.width) - 0.5, f64::from(cam.height) - 0.5);
                let mut n_parts = 0u32;
                for (i, p) in projected.iter().enumerate() {
                    st.parts.push(p.gpu_part());
                    n_parts += 1;
                    let bb = p.bbox();
                    if bb[2] < -0.5 || bb[3] < -0.5 || bb[0] >= wf || bb[1] >= hf {
                        continue;
                    }
                    p.pieces(i as u32, SPACING, &mut st.pieces);
                }
                let n_pieces = (st.pieces.len() - start) as u32;
                st.pieces
                    .resize(start + PIECES_PER_JOB, GpuPiece::default());
                let parts_end = st.parts.len() - n_parts as usize + PARTS_PER_JOB;
                st.parts.resize(parts_end, GpuPart::default());
                st.jobs.push([
                    st.edge_offsets[v],
                    cam.width,
                    cam.height,
                    n_pieces | (n_parts << 16),
                ]);
            }
        }
    }

    /// Grows the job buffers (and the bind group) when `n_jobs` exceeds their capacity.
    fn ensure_capacity(&self, st: &mut State, n_jobs: usize) -> Result<(), GpuError> {
        if st.buffers.as_ref().is_some_and(|b| b.capacity >= n_jobs) {
            return Ok(());
        }
        let capacity = n_jobs.next_power_of_two().max(64);
        let piece_bytes = (capacity * PIECES_PER_JOB * size_of::<GpuPiece>()) as u64;
        let part_bytes = (capacity * PARTS_PER_JOB * size_of::<GpuPart>()) as u64;
        if piece_bytes.max(part_bytes) > self.max_buffer {
            return Err(GpuError::TooLarge(format!(
                "{n_jobs} particle-views need {} MB buffers, the device allows {} MB",
                piece_bytes >> 20,
                self.max_buffer >> 20
            )));
        }
        let d = &self.device;
        let copy = wgpu::BufferUsages::COPY_DST;
        let jobs = storage(d, "jobs", (capacity * 16) as u64, copy);
        let pieces = storage(d, "pieces", piece_bytes, copy);
        let parts = storage(d, "parts", part_bytes, copy);
        let results = storage(
            d,
            "results",
            (capacity * 16) as u64,
            wgpu::BufferUsages::COPY_SRC,
        );
        let readback = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: (capacity * 16) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("contour likelihood"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: self.params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: st.edges.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: jobs.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: pieces.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: parts.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: results.as_entire_binding(),
                },
            ],
        });
        st.buffers = Some(Buffers {
            capacity,
            jobs,
            pieces,
            parts,
            results,
            readback,
            bind_group,
        });
        self.check_errors()
    }

    /// ε̄ per job (the CPU for ambiguous ones), then log P per pose.
    fn finish(&self, st: &mut State, edges: &[EdgeImage], poses: &[[f64; 9]], out: &mut [f64]) {
        let factor = 1.0 / (2.0 * self.cpu.gamma() * self.cpu.gamma());
        let views = self.cpu.cameras().len();
        let mut job = 0;
        for (pose, o) in poses.iter().zip(out.iter_mut()) {
            if !pose.iter().all(|v| v.is_finite()) {
                *o = self.cpu.min_log_likelihood();
                continue;
            }
            let mut total = 0.0;
            for (v, edge) in edges.iter().enumerate().take(views) {
                let [lo, hi, count, amb] = st.results[job];
                job += 1;
                total += if amb != 0 {
                    st.fallbacks += 1;
                    self.cpu.view_error(v, edge, pose, &mut st.scratch)
                } else if count == 0 {
                    1.0
                } else {
                    let sum = (f64::from(hi) * 4_294_967_296.0 + f64::from(lo)) / FIXED_SCALE;
                    (sum / f64::from(count)).clamp(0.0, 1.0)
                };
            }
            *o = -total * factor;
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    use super::*;
    use crate::tests::{SHOULDER, scene};
    use crate::{EdgeParams, EdgeWorkspace, correct_arm};

    fn gpu(cams: Vec<Camera>) -> Option<GpuLikelihood> {
        match GpuLikelihood::new(cams, ArmGeometry::default(), 0.15) {
            Ok(g) => {
                eprintln!("GPU adapter: {}", g.adapter_name());
                Some(g)
            }
            Err(GpuError::NoAdapter(e)) => {
                eprintln!("note: no GPU adapter ({e}); skipping the GPU test");
                None
            }
            Err(e) => panic!("GPU adapter present but unusable: {e}"),
        }
    }

    fn camera(eye: [f64; 3], w: u32, h: u32, distortion: [f64; 5]) -> Camera {
        let mut c = Camera::look_at(
            Vector3::from(eye),
            Vector3::new(0.1, 0.25, 0.95),
            Vector3::z(),
            w,
            h,
            55f64.to_radians(),
        )
        .unwrap();
        c.distortion = distortion;
        c
    }

    fn true_pose() -> [f64; 9] {
        let mut p = [
            SHOULDER[0],
            SHOULDER[1],
            SHOULDER[2],
            0.3,
            0.15,
            0.95,
            0.25,
            0.55,
            0.8,
        ];
        correct_arm(&ArmGeometry::default(), &mut p, None);
        p
    }

    /// Random corrected poses around the true one (elbow and hand within ±25 cm), some far
    /// off, seeded.
    fn random_poses(n: usize, seed: u64) -> Vec<[f64; 9]> {
        let g = ArmGeometry::default();
        let base = true_pose();
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let mut p = base;
                for v in &mut p[3..] {
                    *v += rng.random_range(-0.25..0.25);
                }
                correct_arm(&g, &mut p, None);
                p
            })
            .collect()
    }

    fn edges(cam: &Camera, seed: u64) -> EdgeImage {
        let img = scene().render(cam, &true_pose(), seed).unwrap();
        let mut ws = EdgeWorkspace::new();
        ws.compute(img.view(), &EdgeParams::default())
            .unwrap()
            .clone()
    }

    fn compare(g: &GpuLikelihood, e: &[EdgeImage], poses: &[[f64; 9]]) -> f64 {
        let mut got = vec![0.0; poses.len()];
        g.log_likelihood_batch(e, poses, &mut got).unwrap();
        let mut want = vec![0.0; poses.len()];
        g.cpu_model()
            .log_likelihood_batch(e, poses, &mut want)
            .unwrap();
        let mut worst = 0.0f64;
        for (i, (a, b)) in got.iter().zip(&want).enumerate() {
            assert!(
                (a - b).abs() < 1e-4,
                "pose {i} {:?}: gpu {a} cpu {b}",
                poses[i]
            );
            worst = worst.max((a - b).abs());
        }
        eprintln!(
            "{} poses × {} views: max |Δ log P| = {worst:.2e}, {} views rescored on the CPU",
            poses.len(),
            e.len(),
            g.last_fallbacks()
        );
        worst
    }

    #[test]
    fn gpu_matches_cpu_analytic_single_view() {
        let cam = camera([0.7, 1.9, 1.65], 640, 480, [0.0; 5]);
        let Some(g) = gpu(vec![cam.clone()]) else {
            return;
        };
        let e = [edges(&cam, 3)];
        let poses = random_poses(400, 11);
        compare(&g, &e, &poses);
        let capacity =
            |g: &GpuLikelihood| g.state.lock().unwrap().buffers.as_ref().unwrap().capacity;
        let cap = capacity(&g);
        // Same batch again (buffers and edge image reused), then a smaller batch.
        compare(&g, &e, &poses);
        compare(&g, &e, &poses[..37]);
        assert_eq!(
            capacity(&g),
            cap,
            "buffers reallocated for a batch that did not grow"
        );
    }

    #[test]
    fn gpu_matches_cpu_multi_view_with_distortion() {
        let cams = vec![
            camera(
                [0.7, 1.9, 1.65],
                320,
                240,
                [-0.12, 0.03, 0.001, -0.0005, 0.0],
            ),
            camera([-1.2, 1.2, 1.5], 400, 300, [0.08, -0.02, 0.0, 0.0, 0.004]),
            camera([0.2, -1.4, 1.9], 360, 240, [0.0; 5]),
        ];
        let Some(g) = gpu(cams.clone()) else {
            return;
        };
        let e: Vec<EdgeImage> = cams
            .iter()
            .enumerate()
            .map(|(i, c)| edges(c, 20 + i as u64))
            .collect();
        let poses = random_poses(300, 12);
        compare(&g, &e, &poses);
        // A new frame: new edge images are uploaded.
        let e2: Vec<EdgeImage> = cams
            .iter()
            .enumerate()
            .map(|(i, c)| edges(c, 40 + i as u64))
            .collect();
        compare(&g, &e2, &poses);
    }

    #[test]
    fn gpu_empty_contours_and_edge_cases() {
        let cam = camera([0.7, 1.9, 1.65], 320, 240, [0.0; 5]);
        let Some(g) = gpu(vec![cam.clone(), cam.clone()]) else {
            return;
        };
        let ones = EdgeImage::constant(320, 240, 1.0).unwrap();
        let zeros = EdgeImage::constant(320, 240, 0.0).unwrap();
        let min = -2.0 / (2.0 * 0.15 * 0.15);
        let off = [50.0, 0.0, 1.0, 50.3, 0.0, 1.0, 50.7, 0.0, 1.0];
        let mut nan = true_pose();
        nan[4] = f64::NAN;
        let eye = cam.center();
        let behind = [
            eye.x,
            eye.y + 1.0,
            eye.z,
            eye.x,
            eye.y + 1.2,
            eye.z,
            eye.x,
            eye.y + 1.5,
            eye.z,
        ];
        let poses = [true_pose(), off, nan, behind, true_pose()];
        let mut out = [0.0; 5];
        // |C| = 0 in both views → ε̄ = 1 per view, the minimum.
        g.log_likelihood_batch(&[ones.clone(), ones.clone()], &poses, &mut out)
            .unwrap();
        assert!(out[0].abs() < 1e-6, "{out:?}");
        for o in &out[1..4] {
            assert!((o - min).abs() < 1e-9, "{out:?}");
        }
        assert!(out[4].abs() < 1e-6);
        // One view with edges everywhere, one without: exactly half the minimum.
        g.log_likelihood_batch(&[ones.clone(), zeros.clone()], &poses, &mut out)
            .unwrap();
        assert!((out[0] - min / 2.0).abs() < 1e-6, "{out:?}");
        assert!((out[1] - min).abs() < 1e-9);
        compare(&g, &[ones.clone(), zeros.clone()], &poses);
        // Errors, not panics.
        assert!(
            g.log_likelihood_batch(std::slice::from_ref(&ones), &poses, &mut out)
                .is_err()
        );
        assert!(
            g.log_likelihood_batch(&[ones.clone(), ones.clone()], &poses, &mut out[..2])
                .is_err()
        );
        g.log_likelihood_batch(&[ones.clone(), ones], &[], &mut [])
            .unwrap();
    }

    #[test]
    fn gpu_close_and_large_parts() {
        // A camera about 0.5 m from the arm: parts several times wider than in the other
        // tests, many cut by the image border.
        let cam = camera([0.3, 0.6, 1.1], 320, 240, [0.0; 5]);
        let Some(g) = gpu(vec![cam.clone()]) else {
            return;
        };
        let e = [edges(&cam, 5)];
        compare(&g, &e, &random_poses(200, 13));
    }

    /// Wall time of a 400-pose batch on the GPU and on the CPU (rayon), 640×480, one view.
    /// `cargo test -p actrack-render --features gpu --release -- --ignored --nocapture timing`
    #[test]
    #[ignore = "timing, not a check"]
    fn gpu_timing_400_poses() {
        let cam = camera([0.7, 1.9, 1.65], 640, 480, [0.0; 5]);
        let Some(g) = gpu(vec![cam.clone()]) else {
            return;
        };
        let e = [edges(&cam, 3)];
        let poses = random_poses(400, 11);
        let mut out = vec![0.0; poses.len()];
        let time = |f: &mut dyn FnMut()| {
            f();
            let reps = 20;
            let t = std::time::Instant::now();
            for _ in 0..reps {
                f();
            }
            t.elapsed().as_secs_f64() * 1e3 / f64::from(reps)
        };
        let gpu_ms = time(&mut || g.log_likelihood_batch(&e, &poses, &mut out).unwrap());
        let fallbacks = g.last_fallbacks();
        let cpu_ms = time(&mut || {
            g.cpu_model()
                .log_likelihood_batch(&e, &poses, &mut out)
                .unwrap();
        });
        eprintln!(
            "400 poses, 640×480: GPU ({}) {gpu_ms:.2} ms ({fallbacks} views on the CPU), \
             CPU ({} rayon threads) {cpu_ms:.2} ms",
            g.adapter_name(),
            rayon::current_num_threads()
        );
    }
}
