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
