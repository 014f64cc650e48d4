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
//!
//! # Files
//!
//! This file holds [`GpuLikelihood`] (device, buffers, dispatch, the CPU's share of the sums);
//! `pieces.rs` the CPU's side of a job (parts and outline pieces as the kernel reads them);
//! `shader.wgsl` the kernel; `tests.rs` the comparison with the CPU model.

mod pieces;

use std::sync::{Arc, Mutex, mpsc};

use pieces::{GpuPart, GpuPiece};

use crate::contour::project_prepared;
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

/// The kernel (`shader.wgsl`). One workgroup per job (particle × view); threads stride over
/// the samples of each piece; sums are exact in fixed point (see the module docs). Its
/// constants and the layouts of `Piece` and `Part` must match [`GpuPiece`], [`GpuPart`] and the
/// constants above.
const SHADER: &str = include_str!("shader.wgsl");

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
mod tests;
