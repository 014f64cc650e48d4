//! The edge image G of SPEC §4.1.

use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};
use std::sync::{PoisonError, RwLock, RwLockReadGuard, RwLockWriteGuard};

use crate::{ImageView, RenderError};

/// Parameters of the edge image (SPEC §4.1).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct EdgeParams {
    /// Threshold τ on the normalised gradient magnitude: values above are set to 1 (default 0.2).
    pub tau: f32,
    /// Standard deviation σ_G of the Gaussian smoothing in pixels (default 4; the kernel is
    /// truncated at ±⌈3σ⌉; 0 disables smoothing).
    pub sigma: f32,
    /// Set sub-threshold values to 0 (Deutscher/bodytrack binary map) instead of keeping them.
    pub binary: bool,
    /// The gradient of the colour image instead of the grey one (not in SPEC §4.1): per pixel
    /// the largest Sobel magnitude of R, G and B, so that a boundary between two colours of
    /// the same brightness (a sleeve against a wall of another hue) is an edge too. Grey frames
    /// are unaffected.
    pub colour: bool,
}

impl Default for EdgeParams {
    fn default() -> Self {
        Self {
            tau: 0.2,
            sigma: 4.0,
            binary: false,
            colour: false,
        }
    }
}

impl EdgeParams {
    /// Checks τ ∈ [0, 1] and σ ∈ [0, 100], both finite.
    pub fn validate(&self) -> Result<(), RenderError> {
        if !(self.tau.is_finite() && (0.0..=1.0).contains(&self.tau)) {
            return Err(RenderError::InvalidParameter(format!(
                "edge threshold tau must be in [0, 1], got {}",
                self.tau
            )));
        }
        if !(self.sigma.is_finite() && (0.0..=100.0).contains(&self.sigma)) {
            return Err(RenderError::InvalidParameter(format!(
                "edge smoothing sigma must be in [0, 100] px, got {}",
                self.sigma
            )));
        }
        Ok(())
    }
}

/// The edge image G ∈ [0, 1] of one view and frame, row-major f32, `G[v·w + u]`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EdgeImage {
    width: u32,
    height: u32,
    data: Vec<f32>,
}

impl EdgeImage {
    /// Wraps existing values (e.g. a G computed elsewhere, or a constant for tests). Values are
    /// used as they are; they should lie in [0, 1].
    pub fn from_vec(width: u32, height: u32, data: Vec<f32>) -> Result<Self, RenderError> {
        ImageView::grey_f32(&data, width, height)?;
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// A constant image.
    pub fn constant(width: u32, height: u32, value: f32) -> Result<Self, RenderError> {
        Self::from_vec(width, height, vec![value; width as usize * height as usize])
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The values, row-major.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The values, row-major, by value (to reuse the buffer).
    pub fn into_data(self) -> Vec<f32> {
        self.data
    }

    /// G at integer pixel (u, v); `None` outside the image.
    #[inline]
    pub fn get(&self, u: i64, v: i64) -> Option<f32> {
        if u < 0 || v < 0 || u >= i64::from(self.width) || v >= i64::from(self.height) {
            return None;
        }
        Some(self.data[v as usize * self.width as usize + u as usize])
    }

    /// G at the rounded pixel of (u, v) (SPEC §4.3); `None` outside the image.
    #[inline]
    pub fn sample_nearest(&self, u: f64, v: f64) -> Option<f32> {
        let (ui, vi) = (u.round(), v.round());
        if !(ui >= 0.0 && vi >= 0.0 && ui < f64::from(self.width) && vi < f64::from(self.height)) {
            return None;
        }
        Some(self.data[vi as usize * self.width as usize + ui as usize])
    }

    /// G bilinearly interpolated at (u, v), with clamping at the border; `None` when the
    /// rounded pixel is outside the image (the same support as [`EdgeImage::sample_nearest`]).
    #[inline]
    pub fn sample_bilinear(&self, u: f64, v: f64) -> Option<f32> {
        let (ui, vi) = (u.round(), v.round());
        if !(ui >= 0.0 && vi >= 0.0 && ui < f64::from(self.width) && vi < f64::from(self.height)) {
            return None;
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let uc = u.clamp(0.0, (w - 1) as f64);
        let vc = v.clamp(0.0, (h - 1) as f64);
        let (u0, v0) = (uc.floor() as usize, vc.floor() as usize);
        let (u1, v1) = ((u0 + 1).min(w - 1), (v0 + 1).min(h - 1));
        let (a, b) = ((uc - u0 as f64) as f32, (vc - v0 as f64) as f32);
        let d = &self.data;
        let top = d[v0 * w + u0] * (1.0 - a) + d[v0 * w + u1] * a;
        let bot = d[v1 * w + u0] * (1.0 - a) + d[v1 * w + u1] * a;
        Some(top * (1.0 - b) + bot * b)
    }
}

/// Owns the scratch buffers of the edge-image computation, so that computing G for a stream of
/// frames of one size allocates nothing after the first frame. One workspace per view (or per
/// thread).
#[derive(Debug, Default, Clone)]
pub struct EdgeWorkspace {
    mag: Vec<f32>,
    /// Scratch rows of every worker (one per thread of the current rayon pool).
    workers: Vec<WorkerScratch>,
    kernel: Vec<f32>,
    kernel_sigma: f32,
    /// Ring slots of the vertical Gaussian: for output row y, the slots of rows y − r … y + r
    /// (clamped to the image), `slots[y·(2r+1) + t]`; made for `slots_key` = (h, r).
    slots: Vec<u32>,
    slots_key: (usize, usize),
    out: EdgeImage,
}

/// The scratch rows of one worker: the grey ring of the Sobel pass, the padded row and the
/// ring of horizontally smoothed rows of the Gaussian pass.
#[derive(Debug, Default, Clone)]
struct WorkerScratch {
    grey: Vec<f32>,
    chan: Vec<f32>,
    sv: Vec<f32>,
    dv: Vec<f32>,
    tmp: Vec<f32>,
    pad: Vec<f32>,
    /// The ring of three RGB rows of the colour gradient, as integer planes.
    rgb: Vec<i16>,
    /// Per channel, the vertical sums and differences of the colour gradient's row.
    isv: Vec<i16>,
    idv: Vec<i16>,
    /// The largest squared channel magnitude of the row.
    m2: Vec<i32>,
}

/// Fewest rows per band of the Sobel pass when the edge image is split over threads (its halo
/// is one grey row on either side).
const MIN_SOBEL_ROWS: usize = 16;
/// Sobel bands per thread: small parts, so that a thread that starts late or is interrupted
/// leaves its share to the others.
const SOBEL_BANDS_PER_THREAD: usize = 4;
/// Fewest rows per band of the Gaussian and normalisation passes (their halo is ⌈3σ⌉ rows on
/// either side, smoothed horizontally by both neighbours); one band per thread.
const MIN_GAUSS_ROWS: usize = 32;
/// Most bands of a pass (their locks live on the stack).
const MAX_BANDS: usize = 128;

/// How the passes are split into row bands: `sobel_rows` rows per band of the Sobel pass,
/// `gauss_rows` per band of the Gaussian and normalisation passes (the last band of each
/// shorter).
#[derive(Clone, Copy, Debug)]
struct Split {
    sobel_rows: usize,
    gauss_rows: usize,
    /// Columns per strip of the Gaussian pass; `None`: [`strip_columns`] (the tests force
    /// other widths).
    strip: Option<usize>,
}

impl Split {
    /// The split of an `h`-row image for `threads` threads (one band each on one thread, or
    /// when the image is too small to gain from more).
    fn new(h: usize, threads: usize) -> Self {
        if threads <= 1 {
            return Self::forced(h, 1, 1);
        }
        Self::forced(
            h,
            (h / MIN_SOBEL_ROWS).min(SOBEL_BANDS_PER_THREAD * threads),
            (h / MIN_GAUSS_ROWS).min(threads),
        )
    }

    /// About `sobel` and `gauss` bands (at least one, at most one per row and `MAX_BANDS`).
    fn forced(h: usize, sobel: usize, gauss: usize) -> Self {
        let rows = |bands: usize| h.div_ceil(bands.clamp(1, h.min(MAX_BANDS)));
        Self {
            sobel_rows: rows(sobel),
            gauss_rows: rows(gauss),
            strip: None,
        }
    }
}

/// Bytes of the ring of horizontally smoothed rows that the vertical Gaussian reads for every
/// output row: small enough to stay in L1 (32–48 KiB on current x86-64 cores) beside the rows
/// it writes.
const RING_BYTES: usize = 24 * 1024;

/// Columns per strip of the Gaussian pass for a `w`-wide image and kernel radius `r`: the
/// widest equal strips (a multiple of 8 columns, at least 64) whose ring of 2r+1 rows fits in
/// `RING_BYTES`. At 640 px and σ = 4 (r = 12, 25 rows) that is three strips of 216 columns
/// (ring 21 KiB) instead of one 64 KiB ring, which would be read from L2.
fn strip_columns(w: usize, r: usize) -> usize {
    let widest = (RING_BYTES / ((2 * r + 1) * size_of::<f32>())).max(64);
    let strips = w.div_ceil(widest).max(1);
    w.div_ceil(strips).next_multiple_of(8).min(w)
}

/// Largest value of a slice (0 for an empty slice or all values ≤ 0); 8 lanes so that it
/// vectorises.
// Inlined into the dispatched band kernels (see `EdgeWorkspace::compute`).
#[allow(clippy::inline_always)]
#[inline(always)]
fn max_value(data: &[f32]) -> f32 {
    let mut lanes = [0f32; 8];
    let mut chunks = data.chunks_exact(8);
    for c in &mut chunks {
        for i in 0..8 {
            lanes[i] = if c[i] > lanes[i] { c[i] } else { lanes[i] };
        }
    }
    let mut m = chunks
        .remainder()
        .iter()
        .fold(0f32, |m, &v| if v > m { v } else { m });
    for l in lanes {
        if l > m {
            m = l;
        }
    }
    m
}

/// Which instruction set the band kernels run with: the best the CPU has (pulp's run-time
/// dispatch), or pulp's scalar (baseline x86-64) variant for the tests.
#[derive(Clone, Copy)]
enum Isa {
    Dispatch(pulp::Arch),
    #[cfg(test)]
    Scalar,
}

impl Isa {
    #[inline]
    fn run<Op: pulp::WithSimd>(self, op: Op) -> Op::Output {
        match self {
            Self::Dispatch(arch) => arch.dispatch(op),
            #[cfg(test)]
            Self::Scalar => {
                use pulp::Simd;
                pulp::Scalar::new().vectorize(op)
            }
        }
    }
}

/// The maximum over the bands of a pass, shared by the workers. Band maxima are never negative
/// or NaN (`max_value`), and for such f32 the order of the bits is the order of the values, so
/// `fetch_max` on the bits gives the maximum, whatever the order of the bands.
struct SharedMax(AtomicU32);

impl SharedMax {
    fn new() -> Self {
        Self(AtomicU32::new(0))
    }

    fn add(&self, v: f32) {
        self.0.fetch_max(v.to_bits(), Ordering::AcqRel);
    }

    fn get(&self) -> f32 {
        f32::from_bits(self.0.load(Ordering::Acquire))
    }
}

/// Waits until `count` reaches `target`, i.e. until the other workers have finished the bands
/// of the previous pass that they claimed (a band is only ever claimed by a worker that
/// computes it at once, so the wait is short). Spins briefly, then yields the core.
fn wait_for(count: &AtomicUsize, target: usize) {
    let mut spins = 0u32;
    while count.load(Ordering::Acquire) < target {
        if spins < 2048 {
            spins += 1;
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
    }
}

/// Runs `job` once with each of `workers`, in parallel on the current rayon pool (the first on
/// the calling thread; `rayon::join`, so nothing is allocated).
fn run_workers<F>(workers: &mut [WorkerScratch], job: &F)
where
    F: Fn(&mut WorkerScratch) + Sync,
{
    match workers {
        [] => {}
        [one] => job(one),
        [first, rest @ ..] => {
            rayon::join(|| job(first), || run_workers(rest, job));
        }
    }
}

/// A read lock (a poisoned lock still holds valid numbers: its writers only write values).
fn read<T>(l: &RwLock<T>) -> RwLockReadGuard<'_, T> {
    l.read().unwrap_or_else(PoisonError::into_inner)
}

/// A write lock (see [`read`]).
fn write<T>(l: &RwLock<T>) -> RwLockWriteGuard<'_, T> {
    l.write().unwrap_or_else(PoisonError::into_inner)
}

/// The rows of an image held in bands of `rows` rows of `w` values.
#[derive(Clone, Copy)]
struct BandRows<'a> {
    bands: &'a [&'a [f32]],
    rows: usize,
    w: usize,
}

impl BandRows<'_> {
    // Inlined into the dispatched band kernels (see `EdgeWorkspace::compute`).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn row(&self, y: usize) -> &[f32] {
        &self.bands[y / self.rows][(y % self.rows) * self.w..][..self.w]
    }
}

impl EdgeWorkspace {
    /// An empty workspace; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// Computes G of SPEC §4.1 for one frame: grey conversion (0.299 R + 0.587 G + 0.114 B),
    /// Sobel/8, magnitude, normalisation by the maximum, threshold τ (values above set to 1,
    /// values below kept or, with `binary`, zeroed), separable Gaussian σ_G truncated at ±⌈3σ⌉
    /// with clamped borders, normalisation by the maximum. A frame without any gradient gives
    /// G ≡ 0. The result lives in the workspace until the next call (clone it to keep it).
    ///
    /// The passes are split into row bands that the threads of the current rayon pool claim
    /// in turn, in one `rayon::join` per frame: grey + Sobel + max (four bands per thread of
    /// at least 16 rows, 1-row halo), threshold + horizontal Gaussian + vertical Gaussian + max
    /// (one band per thread of at least 32 rows, ⌈3σ⌉-row halo smoothed by both neighbours),
    /// normalisation (the same bands). A band of one pass starts once every band of the
    /// previous pass is done and its maximum known. Every value is computed by the same
    /// operations whatever the split, and the maxima do not depend on the order, so G is
    /// bit-identical for every number of threads.
    pub fn compute(
        &mut self,
        frame: ImageView<'_>,
        params: &EdgeParams,
    ) -> Result<&EdgeImage, RenderError> {
        frame.validate()?;
        params.validate()?;
        let h = frame.size().1 as usize;
        let threads = rayon::current_num_threads().max(1);
        // The kernels are compiled twice more, with AVX2 (+ FMA, BMI, …) and with AVX-512
        // (pulp's V3 and V4), and the best variant the CPU supports is chosen at run time (pulp;
        // no `target-cpu` flag, so the binaries run on any x86-64); every band of every pass is
        // one dispatched call. Every helper below is `#[inline(always)]` so that it is compiled
        // inside the dispatched function. No FMA contraction happens (Rust never fuses
        // `a * b + c`), so every variant gives bit-identical G.
        self.compute_split(
            &frame,
            params,
            Split::new(h, threads),
            threads,
            Isa::Dispatch(pulp::Arch::new()),
        );
        Ok(&self.out)
    }

    /// The body of [`EdgeWorkspace::compute`] on validated input, split as `split` and run by
    /// `threads` workers.
    fn compute_split(
        &mut self,
        frame: &ImageView<'_>,
        params: &EdgeParams,
        split: Split,
        threads: usize,
        isa: Isa,
    ) {
        let (w32, h32) = frame.size();
        let (w, h) = (w32 as usize, h32 as usize);
        let n = w * h;
        let (nb, ng) = (h.div_ceil(split.sobel_rows), h.div_ceil(split.gauss_rows));
        let threads = threads.max(1);
        if self.workers.len() < threads {
            self.workers.resize_with(threads, WorkerScratch::default);
        }
        self.mag.resize(n, 0.0);
        self.out.width = w32;
        self.out.height = h32;
        self.out.data.resize(n, 0.0);
        if params.sigma > 0.0 {
            self.make_kernel(params.sigma);
            self.make_slots(h);
        }
        let frame = *frame;
        let (kernel, slots) = (&self.kernel[..], &self.slots[..]);
        let strip = split
            .strip
            .unwrap_or_else(|| strip_columns(w, kernel.len().saturating_sub(1)))
            .clamp(1, w);
        let (sigma, tau, binary) = (params.sigma, params.tau, params.binary);
        // Every band behind its own lock: written by the one worker that claims it, read by
        // the next pass (the Gaussian reads its neighbours' magnitudes too).
        let mut bands = self.mag.chunks_mut(split.sobel_rows * w);
        let mag: [RwLock<&mut [f32]>; MAX_BANDS] =
            std::array::from_fn(|_| RwLock::new(bands.next().unwrap_or_default()));
        let mut bands = self.out.data.chunks_mut(split.gauss_rows * w);
        let out: [RwLock<&mut [f32]>; MAX_BANDS] =
            std::array::from_fn(|_| RwLock::new(bands.next().unwrap_or_default()));
        // Bands are numbered pass by pass (Sobel 0 … nb − 1, Gaussian nb … nb + ng − 1,
        // normalisation after them) and claimed in that order.
        let next = AtomicUsize::new(0);
        let done = [AtomicUsize::new(0), AtomicUsize::new(0)];
        let (max_g, max_out) = (SharedMax::new(), SharedMax::new());
        let job = |ws: &mut WorkerScratch| {
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i < nb {
                    let mut m = write(&mag[i]);
                    max_g.add(isa.run(SobelBand {
                        s: ws,
                        frame: &frame,
                        y0: i * split.sobel_rows,
                        h,
                        mag: &mut m,
                        colour: params.colour,
                    }));
                    drop(m);
                    done[0].fetch_add(1, Ordering::AcqRel);
                } else if i < nb + ng {
                    wait_for(&done[0], nb);
                    let mg = max_g.get();
                    let b = i - nb;
                    let mut o = write(&out[b]);
                    if mg > 0.0 && mg.is_finite() {
                        let guards: [Option<RwLockReadGuard<'_, &mut [f32]>>; MAX_BANDS] =
                            std::array::from_fn(|j| (j < nb).then(|| read(&mag[j])));
                        let slices: [&[f32]; MAX_BANDS] =
                            std::array::from_fn(|j| guards[j].as_deref().map_or(&[][..], |g| g));
                        let mag = BandRows {
                            bands: &slices[..nb],
                            rows: split.sobel_rows,
                            w,
                        };
                        let thr = Threshold {
                            inv: 1.0 / mg,
                            tau,
                            binary,
                        };
                        let y0 = b * split.gauss_rows;
                        max_out.add(if sigma > 0.0 {
                            isa.run(GaussBand {
                                s: ws,
                                mag,
                                k: kernel,
                                slots,
                                w,
                                h,
                                strip,
                                y0,
                                out: &mut o,
                                thr,
                            })
                        } else {
                            isa.run(ThresholdBand {
                                mag,
                                y0,
                                out: &mut o,
                                thr,
                            })
                        });
                    }
                    drop(o);
                    done[1].fetch_add(1, Ordering::AcqRel);
                } else if i < nb + 2 * ng {
                    wait_for(&done[1], ng);
                    let (mg, mo) = (max_g.get(), max_out.get());
                    let mut o = write(&out[i - nb - ng]);
                    if mg > 0.0 && mg.is_finite() && mo > 0.0 {
                        isa.run(ScaleBand {
                            out: &mut o,
                            inv: 1.0 / mo,
                        });
                    } else {
                        o.fill(0.0);
                    }
                } else {
                    break;
                }
            }
        };
        run_workers(&mut self.workers[..threads], &job);
    }

    /// [`EdgeWorkspace::compute_split`] with `bands` bands in every pass, on the calling
    /// thread (the tests' forced splits).
    #[cfg(test)]
    fn compute_banded(
        &mut self,
        frame: &ImageView<'_>,
        params: &EdgeParams,
        bands: usize,
        isa: Isa,
    ) {
        let h = frame.size().1 as usize;
        self.compute_split(frame, params, Split::forced(h, bands, bands), 1, isa);
    }

    /// [`EdgeWorkspace::compute`] into `out` without copying: the result's buffer is swapped
    /// into `out` and `out`'s old buffer becomes the workspace's next output buffer, so a caller
    /// that keeps its images across frames allocates nothing after the first two frames.
    pub fn compute_into(
        &mut self,
        frame: ImageView<'_>,
        params: &EdgeParams,
        out: &mut EdgeImage,
    ) -> Result<(), RenderError> {
        self.compute(frame, params)?;
        std::mem::swap(&mut self.out, out);
        Ok(())
    }

    /// The last result ([`EdgeWorkspace::compute`]; after [`EdgeWorkspace::compute_into`] it
    /// holds the caller's previous image).
    pub fn edge_image(&self) -> &EdgeImage {
        &self.out
    }

    /// The ring slots of every output row of the vertical Gaussian (see `slots`): row yy lives
    /// in slot yy mod (2r + 1).
    fn make_slots(&mut self, h: usize) {
        let r = self.kernel.len() - 1;
        if self.slots_key == (h, r) && !self.slots.is_empty() {
            return;
        }
        let ring = 2 * r + 1;
        self.slots.clear();
        for y in 0..h {
            for t in 0..ring {
                let yy = (y + t).saturating_sub(r).min(h - 1);
                self.slots.push((yy % ring) as u32);
            }
        }
        self.slots_key = (h, r);
    }

    fn make_kernel(&mut self, sigma: f32) {
        if self.kernel_sigma.to_bits() == sigma.to_bits() && !self.kernel.is_empty() {
            return;
        }
        let radius = (3.0 * sigma).ceil().max(1.0) as usize;
        self.kernel.clear();
        let s2 = 2.0 * f64::from(sigma) * f64::from(sigma);
        for j in 0..=radius {
            self.kernel.push((-((j * j) as f64) / s2).exp() as f32);
        }
        let sum: f32 = self.kernel[0] + 2.0 * self.kernel[1..].iter().sum::<f32>();
        for k in &mut self.kernel {
            *k /= sum;
        }
        self.kernel_sigma = sigma;
    }
}

/// Sobel (3×3) gradient magnitude of the frame's grey values, rows `y0 …` of the band into
/// `mag` (the band's rows), borders clamped; returns max(mag). Grey rows (the band's and one
/// halo row on either side) are converted on the fly into a ring of three rows. Separable: per
/// row, the vertical smoothing `a + 2c + b` and the vertical difference `b − a`, then
/// horizontal difference / smoothing of those. The 1/8 of SPEC §4.1 is left out here: it is a
/// power of two, so it cancels exactly (bit for bit) in the normalisation by max(g) that
/// follows. With `colour` (and a colour frame) the band is computed once per channel of R, G
/// and B and the largest magnitude kept.
struct SobelBand<'a, 'f> {
    s: &'a mut WorkerScratch,
    frame: &'a ImageView<'f>,
    y0: usize,
    h: usize,
    mag: &'a mut [f32],
    colour: bool,
}

impl pulp::WithSimd for SobelBand<'_, '_> {
    type Output = f32;

    // Inlined into the dispatched function (see `EdgeWorkspace::compute`).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f32 {
        let Self {
            s,
            frame,
            y0,
            h,
            mag,
            colour,
        } = self;
        match *frame {
            ImageView::Rgb8 { data, width, .. } if colour => {
                sobel_rgb_rows(s, data, width as usize, y0, h, mag)
            }
            _ => sobel_rows(s, frame, y0, h, mag),
        }
    }
}

/// The colour body of [`SobelBand`]: per pixel the largest Sobel magnitude of R, G and B of
/// the RGB rows `data` (`w` pixels wide) into `mag`; returns max(mag). One pass over the band
/// in integers: the channel values and Sobel sums (|gx|, |gy| ≤ 1020) in i16, the squared
/// magnitude gx² + gy² ≤ 2·1020² in i32. Each is an integer below 2²⁴, so it is exactly what
/// the f32 arithmetic of [`sobel_rows`] gives on each channel. The largest of the three squares is taken before the one square root, which is
/// the largest of the three roots (the root is monotone and correctly rounded): G is bit for
/// bit that of the channel-by-channel computation, for a third of its square roots and none of
/// its conversions to f32 but the last.
// Inlined into the dispatched function (see `EdgeWorkspace::compute`).
#[allow(clippy::inline_always)]
#[inline(always)]
fn sobel_rgb_rows(
    s: &mut WorkerScratch,
    data: &[u8],
    w: usize,
    y0: usize,
    h: usize,
    mag: &mut [f32],
) -> f32 {
    // Ring of three rows, each as three planes R, G, B: `rgb[(slot·3 + c)·w + x]`.
    s.rgb.resize(9 * w, 0);
    s.isv.resize(3 * w, 0);
    s.idv.resize(3 * w, 0);
    s.m2.resize(w, 0);
    let mut slot_row = [usize::MAX; 3];
    let mut lanes = [0f32; 8];
    for y in y0..y0 + mag.len() / w {
        let ys = [y.saturating_sub(1), y, (y + 1).min(h - 1)];
        for &yy in &ys {
            let slot = yy % 3;
            if slot_row[slot] != yy {
                let planes = &mut s.rgb[slot * 3 * w..][..3 * w];
                let (r, rest) = planes.split_at_mut(w);
                let (g, b) = rest.split_at_mut(w);
                let (px, _) = data[3 * yy * w..3 * (yy + 1) * w].as_chunks::<3>();
                for (((r, g), b), px) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()).zip(px) {
                    *r = i16::from(px[0]);
                    *g = i16::from(px[1]);
                    *b = i16::from(px[2]);
                }
                slot_row[slot] = yy;
            }
        }
        for c in 0..3 {
            let plane = |yy: usize| &s.rgb[((yy % 3) * 3 + c) * w..][..w];
            let (a, m, b) = (plane(ys[0]), plane(ys[1]), plane(ys[2]));
            let sv = &mut s.isv[c * w..][..w];
            let dv = &mut s.idv[c * w..][..w];
            for x in 0..w {
                sv[x] = a[x] + 2 * m[x] + b[x];
                dv[x] = b[x] - a[x];
            }
        }
        let m2 = &mut s.m2[..w];
        for c in 0..3 {
            let (sv, dv) = (&s.isv[c * w..][..w], &s.idv[c * w..][..w]);
            let at = |x_l: usize, x: usize, x_r: usize| {
                let gx = i32::from(sv[x_r] - sv[x_l]);
                let gy = i32::from(dv[x_l] + 2 * dv[x] + dv[x_r]);
                gx * gx + gy * gy
            };
            let merge = |old: i32, v: i32| if c == 0 || v > old { v } else { old };
            if w >= 3 {
                let n = w - 2;
                let (sl, sr) = (&sv[..n], &sv[2..2 + n]);
                let (dl, dc, dr) = (&dv[..n], &dv[1..=n], &dv[2..2 + n]);
                let o = &mut m2[1..=n];
                for x in 0..n {
                    let gx = i32::from(sr[x] - sl[x]);
                    let gy = i32::from(dl[x] + 2 * dc[x] + dr[x]);
                    o[x] = merge(o[x], gx * gx + gy * gy);
                }
            }
            m2[0] = merge(m2[0], at(0, 0, 1.min(w - 1)));
            if w > 1 {
                m2[w - 1] = merge(m2[w - 1], at(w - 2, w - 1, w - 1));
            }
        }
        let out = &mut mag[(y - y0) * w..][..w];
        #[allow(clippy::cast_precision_loss)] // below 2²⁴: exact
        for (o, &v) in out.iter_mut().zip(m2.iter()) {
            *o = (v as f32).sqrt();
        }
        let m = max_value(out);
        lanes[y % 8] = if m > lanes[y % 8] { m } else { lanes[y % 8] };
    }
    max_value(&lanes)
}

/// The grey body of [`SobelBand`]: the Sobel magnitude of the frame's grey rows into `mag`;
/// returns max(mag).
// `hypot` does not vectorise; |g| ≤ 255·2, so the plain form cannot overflow. Inlined into the
// dispatched function (see `EdgeWorkspace::compute`).
#[allow(clippy::imprecise_flops, clippy::inline_always)]
#[inline(always)]
fn sobel_rows(
    s: &mut WorkerScratch,
    frame: &ImageView<'_>,
    y0: usize,
    h: usize,
    mag: &mut [f32],
) -> f32 {
    let w = frame.size().0 as usize;
    s.sv.resize(w, 0.0);
    s.dv.resize(w, 0.0);
    s.grey.resize(3 * w, 0.0);
    let mut slot_row = [usize::MAX; 3];
    let mut lanes = [0f32; 8];
    for y in y0..y0 + mag.len() / w {
        let ys = [y.saturating_sub(1), y, (y + 1).min(h - 1)];
        for &yy in &ys {
            if slot_row[yy % 3] != yy {
                grey_row(frame, yy, &mut s.chan, &mut s.grey[(yy % 3) * w..][..w]);
                slot_row[yy % 3] = yy;
            }
        }
        let a = &s.grey[(ys[0] % 3) * w..][..w];
        let c = &s.grey[(ys[1] % 3) * w..][..w];
        let b = &s.grey[(ys[2] % 3) * w..][..w];
        {
            let (svr, dvr) = (&mut s.sv[..w], &mut s.dv[..w]);
            for x in 0..w {
                svr[x] = a[x] + 2.0 * c[x] + b[x];
                dvr[x] = b[x] - a[x];
            }
        }
        let out = &mut mag[(y - y0) * w..][..w];
        let (sv, dv) = (&s.sv[..w], &s.dv[..w]);
        let at = |x_l: usize, x: usize, x_r: usize| {
            let gx = sv[x_r] - sv[x_l];
            let gy = dv[x_l] + 2.0 * dv[x] + dv[x_r];
            (gx * gx + gy * gy).sqrt()
        };
        if w >= 3 {
            let n = w - 2;
            let (sl, sr) = (&sv[..n], &sv[2..2 + n]);
            let (dl, dc, dr) = (&dv[..n], &dv[1..=n], &dv[2..2 + n]);
            let o = &mut out[1..=n];
            for x in 0..n {
                let gx = sr[x] - sl[x];
                let gy = dl[x] + 2.0 * dc[x] + dr[x];
                o[x] = (gx * gx + gy * gy).sqrt();
            }
        }
        out[0] = at(0, 0, 1.min(w - 1));
        if w > 1 {
            out[w - 1] = at(w - 2, w - 1, w - 1);
        }
        let m = max_value(out);
        lanes[y % 8] = if m > lanes[y % 8] { m } else { lanes[y % 8] };
    }
    max_value(&lanes)
}

/// Threshold + separable Gaussian `mag → out` for the band's rows `y0 …` (`out` holds the
/// band's rows), borders clamped; returns max(out). The horizontal pass writes into a ring of
/// 2r+1 rows that the vertical pass reads, so the intermediate image never leaves the cache;
/// the r rows above and below the band are smoothed horizontally by this band as well. The band
/// is processed in column strips of `strip` columns (each with its r-column halo), so that the
/// ring stays in L1 also for wide images.
struct GaussBand<'a> {
    s: &'a mut WorkerScratch,
    mag: BandRows<'a>,
    k: &'a [f32],
    slots: &'a [u32],
    w: usize,
    h: usize,
    /// Columns per strip ([`strip_columns`]).
    strip: usize,
    y0: usize,
    out: &'a mut [f32],
    thr: Threshold,
}

impl pulp::WithSimd for GaussBand<'_> {
    type Output = f32;

    // Inlined into the dispatched function (see `EdgeWorkspace::compute`).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f32 {
        let Self {
            s,
            mag,
            k,
            slots,
            w,
            h,
            strip,
            y0,
            out,
            thr,
        } = self;
        let r = k.len() - 1;
        let ring = 2 * r + 1;
        let rows = out.len() / w;
        s.tmp.resize(ring * strip, 0.0);
        s.pad.resize(strip + 2 * r, 0.0);
        let mut lanes = [0f32; 8];
        // Strip by strip, so that the ring the vertical pass reads stays in L1. Every value is
        // computed by the same operations as with one strip of the whole width.
        let mut x0 = 0;
        while x0 < w {
            let sw = strip.min(w - x0);
            // The strip's padded columns x0 − r … x0 + sw + r − 1, clamped to the image: the
            // part inside the image and the copies of the border columns on either side.
            let lo = x0.saturating_sub(r);
            let hi = (x0 + sw + r).min(w);
            let left = lo + r - x0;
            // Row `yy` lives in ring slot `yy mod ring`.
            let mut next = y0.saturating_sub(r);
            let mut slot = next % ring;
            for y in y0..y0 + rows {
                while next <= (y + r).min(h - 1) {
                    let src = &mag.row(next)[lo..hi];
                    let pad = &mut s.pad[..sw + 2 * r];
                    for (p, &g) in pad[left..left + src.len()].iter_mut().zip(src) {
                        *p = thr.apply(g);
                    }
                    let (first, last) = (pad[left], pad[left + src.len() - 1]);
                    pad[..left].fill(first);
                    pad[left + src.len()..].fill(last);
                    gauss_row(pad, k, &mut s.tmp[slot * sw..][..sw]);
                    next += 1;
                    // The slot of row `next`, tracked without a division.
                    slot = if slot + 1 == ring { 0 } else { slot + 1 };
                }
                let dst = &mut out[(y - y0) * w + x0..][..sw];
                gauss_col(&s.tmp, &slots[y * ring..][..ring], k, dst);
                let m = max_value(dst);
                lanes[y % 8] = if m > lanes[y % 8] { m } else { lanes[y % 8] };
            }
            x0 += sw;
        }
        max_value(&lanes)
    }
}

/// Threshold only (σ = 0) of the band's rows `y0 …` into `out`; returns max(out).
struct ThresholdBand<'a> {
    mag: BandRows<'a>,
    y0: usize,
    out: &'a mut [f32],
    thr: Threshold,
}

impl pulp::WithSimd for ThresholdBand<'_> {
    type Output = f32;

    // Inlined into the dispatched function (see `EdgeWorkspace::compute`).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f32 {
        let Self { mag, y0, out, thr } = self;
        for (dy, row) in out.chunks_exact_mut(mag.w).enumerate() {
            for (o, &g) in row.iter_mut().zip(mag.row(y0 + dy)) {
                *o = thr.apply(g);
            }
        }
        max_value(out)
    }
}

/// The final normalisation `out *= inv` of one band (returns 0).
struct ScaleBand<'a> {
    out: &'a mut [f32],
    inv: f32,
}

impl pulp::WithSimd for ScaleBand<'_> {
    type Output = f32;

    // Inlined into the dispatched function (see `EdgeWorkspace::compute`).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> f32 {
        for g in self.out.iter_mut() {
            *g *= self.inv;
        }
        0.0
    }
}

/// Normalisation by max(g) and the threshold τ of SPEC §4.1 steps 3–4.
#[derive(Clone, Copy)]
struct Threshold {
    inv: f32,
    tau: f32,
    binary: bool,
}

impl Threshold {
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn apply(self, g: f32) -> f32 {
        let v = g * self.inv;
        if v > self.tau {
            1.0
        } else if self.binary {
            0.0
        } else {
            v
        }
    }
}

/// The grey image of SPEC §4.1 step 1, converted as [`EdgeWorkspace::compute`] converts it
/// (0.299 R + 0.587 G + 0.114 B for colour frames), row-major into `out` (resized).
pub fn grey_image(frame: ImageView<'_>, out: &mut Vec<f32>) {
    let (w, h) = frame.size();
    let (w, h) = (w as usize, h as usize);
    // Every value is written below: no clearing.
    out.resize(w * h, 0.0);
    if let ImageView::Rgb8 { data, .. } = frame {
        pulp::Arch::new().dispatch(GreyRgb {
            data: &data[..3 * w * h],
            out,
        });
        return;
    }
    for (y, row) in out.chunks_exact_mut(w).enumerate().take(h) {
        // Grey rows need no scratch (an empty `Vec` allocates nothing).
        grey_row(&frame, y, &mut Vec::new(), row);
    }
}

/// The grey values of RGB pixels, `out[i] = 0.299 R + 0.587 G + 0.114 B` of pixel i, in the
/// f32 operations of `grey_row` (bit-identical), compiled for the best instruction set the CPU
/// has: the stride-3 loads vectorise with AVX2 or AVX-512.
struct GreyRgb<'a> {
    data: &'a [u8],
    out: &'a mut [f32],
}

impl pulp::WithSimd for GreyRgb<'_> {
    type Output = ();

    // Inlined into the dispatched function.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let (px, _) = self.data.as_chunks::<3>();
        for (g, p) in self.out.iter_mut().zip(px) {
            *g = 0.299 * f32::from(p[0]) + 0.587 * f32::from(p[1]) + 0.114 * f32::from(p[2]);
        }
    }
}

/// One grey row (0.299 R + 0.587 G + 0.114 B for colour frames). Colour rows are first widened
/// to f32 channel by channel into `chan` (contiguous, so it vectorises), then combined with a
/// stride-3 read: about twice as fast as converting pixel by pixel.
// Inlined into the dispatched `compute_kernels` (see there).
#[allow(clippy::inline_always)]
#[inline(always)]
fn grey_row(frame: &ImageView<'_>, y: usize, chan: &mut Vec<f32>, dst: &mut [f32]) {
    let w = dst.len();
    match *frame {
        ImageView::Rgb8 { data, .. } => {
            chan.resize(3 * w, 0.0);
            for (c, &b) in chan.iter_mut().zip(&data[3 * y * w..3 * (y + 1) * w]) {
                *c = f32::from(b);
            }
            let (px, _) = chan.as_chunks::<3>();
            for (g, px) in dst.iter_mut().zip(px) {
                *g = 0.299 * px[0] + 0.587 * px[1] + 0.114 * px[2];
            }
        }
        ImageView::Grey8 { data, .. } => {
            for (g, &p) in dst.iter_mut().zip(&data[y * w..(y + 1) * w]) {
                *g = f32::from(p);
            }
        }
        ImageView::GreyF32 { data, .. } => {
            for (g, &p) in dst.iter_mut().zip(&data[y * w..(y + 1) * w]) {
                *g = if p.is_finite() { p } else { 0.0 };
            }
        }
    }
}

/// Horizontal Gaussian of a padded row (`pad.len() == dst.len() + 2r`). Blocks of `BLOCK`
/// columns keep their accumulators in registers across all taps; the symmetric kernel folds
/// each pair of taps into one multiplication. The last block is aligned with the end of the
/// row (it may overlap the previous one and recompute a few identical values).
// Inlined into the dispatched `compute_kernels` (see there).
#[allow(clippy::inline_always)]
#[inline(always)]
fn gauss_row(pad: &[f32], k: &[f32], dst: &mut [f32]) {
    let r = k.len() - 1;
    let w = dst.len();
    if w < BLOCK {
        for (x, o) in dst.iter_mut().enumerate() {
            let mut acc = k[0] * pad[x + r];
            for (j, &kj) in k.iter().enumerate().skip(1) {
                acc += kj * (pad[x + r - j] + pad[x + r + j]);
            }
            *o = acc;
        }
        return;
    }
    let mut x = 0;
    loop {
        let x0 = x.min(w - BLOCK);
        let win = &pad[x0..x0 + 2 * r + BLOCK];
        let mut acc = [0f32; BLOCK];
        for (a, &c) in acc.iter_mut().zip(&win[r..r + BLOCK]) {
            *a = k[0] * c;
        }
        for (j, &kj) in k.iter().enumerate().skip(1) {
            let lo = &win[r - j..r - j + BLOCK];
            let hi = &win[r + j..r + j + BLOCK];
            for ((a, &l), &h) in acc.iter_mut().zip(lo).zip(hi) {
                *a += kj * (l + h);
            }
        }
        dst[x0..x0 + BLOCK].copy_from_slice(&acc);
        if x0 == w - BLOCK {
            break;
        }
        x += BLOCK;
    }
}

/// Vertical Gaussian of one output row from the rows in ring slots `slots` (rows y−r … y+r,
/// `dst.len()` values per slot) of `src`. Whole rows at a time, two pairs of taps per sweep:
/// every sweep streams four source rows sequentially (friendlier to the prefetcher than 2r+1
/// interleaved streams) and the output row stays in L1.
// Inlined into the dispatched `compute_kernels` (see there).
#[allow(clippy::inline_always)]
#[inline(always)]
fn gauss_col(src: &[f32], slots: &[u32], k: &[f32], dst: &mut [f32]) {
    let r = k.len() - 1;
    let w = dst.len();
    let row = |t: usize| &src[slots[t] as usize * w..][..w];
    for (o, &c) in dst.iter_mut().zip(row(r)) {
        *o = k[0] * c;
    }
    let mut j = 1;
    while j < r {
        let (k1, k2) = (k[j], k[j + 1]);
        let (a1, b1, a2, b2) = (row(r - j), row(r + j), row(r - j - 1), row(r + j + 1));
        for ((((o, &a1), &b1), &a2), &b2) in dst.iter_mut().zip(a1).zip(b1).zip(a2).zip(b2) {
            *o += k1 * (a1 + b1) + k2 * (a2 + b2);
        }
        j += 2;
    }
    if j == r {
        let kj = k[j];
        for ((o, &a), &b) in dst.iter_mut().zip(row(r - j)).zip(row(r + j)) {
            *o += kj * (a + b);
        }
    }
}

/// Columns per register block of the Gaussian passes (eight SSE registers of accumulators).
const BLOCK: usize = 32;

#[cfg(test)]
mod tests;
