//! Perona-Malik anisotropic diffusion of depth: the CPU twin of shaders/diffusion.wgsl.
//!
//! The equation is the paper's: du/dt = div(c ∇u) over 4-neighbours, with conductance
//! c(d) = exp(-(d/kappa)^2) of the depth difference d, and no flux into or out of invalid
//! pixels (0), so holes never bleed into surfaces.
//!
//! The reference integrates it explicitly: 60 steps of 0.2, a step stable only below
//! 0.25. Here each step is semi-implicit and locally one-dimensional (LOD splitting):
//! an implicit solve along every row, then one along every column, with the conductances
//! taken from the pass's input. Each solve is a tridiagonal system (the Thomas
//! algorithm), stable at any step length, so 4 steps cover the reference's time of 12 at
//! a quarter of the cost. Weickert, ter Haar Romeny & Viergever ("Efficient and reliable
//! schemes for nonlinear diffusion filtering", IEEE TIP 7(3), 1998) give the scheme;
//! README has its accuracy against the explicit one, frame by frame.
//!
//! Along a line, with s the step's time and coupling k_i = s c(u_{i+1} - u_i) (0 when
//! either pixel is invalid), v solves v_i - k_{i-1} (v_{i-1} - v_i) - k_i (v_{i+1} - v_i) = u_i,
//! written for the change v - u.

use std::ops::Range;

use rayon::prelude::*;

use crate::extract::Grid;
use crate::extract::params::DiffusionSchedule;

/// exp(-(d/kappa)^2) as 2^-t: the integer part of t by the exponent bits, the
/// fraction by a degree-4 minimax polynomial of 2^-f on [0, 1) (under 3e-6; with the
/// rounding of t, under 5e-6 of exp), branch-free. shaders/diffusion.wgsl has the same
/// function, so both twins compute the same conductance.
#[inline(always)]
pub fn conductance(d: f32, inv_kappa: f32) -> f32 {
    let s = d * inv_kappa;
    // Capped at 2^-100: smaller values would turn denormal and crawl.
    let t = (s * s * std::f32::consts::LOG2_E).min(100.0);
    // SAFETY: t is in [0, 100] (min() returns 100 for NaN), so the cast is exact; the
    // unchecked cast is what lets the loop vectorise.
    let n: i32 = unsafe { t.to_int_unchecked() };
    let f = t - n as f32;
    let p = EXP2_NEG[0] + f * (EXP2_NEG[1] + f * (EXP2_NEG[2] + f * (EXP2_NEG[3] + f * EXP2_NEG[4])));
    f32::from_bits(((127 - n) as u32) << 23) * p
}

/// 2^-f ~ Σ EXP2_NEG[k] f^k on [0, 1), minimax in relative error (Lawson's algorithm).
pub const EXP2_NEG: [f32; 5] = [0.9999974, -0.6930302, 0.23934102, -0.05307402, 0.0067670685];

/// The coupling of neighbours z and q in a step of time `step`: none unless both are valid.
#[inline(always)]
pub fn coupling(z: f32, q: f32, step: f32, inv_kappa: f32) -> f32 {
    step * conductance(q - z, inv_kappa) * (((z != 0.0) & (q != 0.0)) as u32 as f32)
}

/// Diffuses depth in metres (0 = invalid) for `time` (in the reference's units: its 60
/// steps of 0.2 are 12) in `steps` semi-implicit steps. No steps or no time: unchanged.
pub fn diffuse(depth: &Grid<f32>, time: f32, steps: u32, kappa: f32) -> Grid<f32> {
    let mut u = depth.clone();
    let DiffusionSchedule { steps, step, inv_kappa } = DiffusionSchedule::new(time, steps, kappa);
    if steps == 0 || u.data.is_empty() {
        return u;
    }
    // The column pass cannot write where it reads (other stripes still read those rows):
    // it writes this second image, and the two swap.
    let mut next = Vec::new();
    // Lines a task: the same for every pass of one image on one pool.
    let (rows_a_band, columns_a_stripe) = (lanes_for(u.height), lanes_for(u.width));
    for _ in 0..steps {
        solve_rows(&mut u, rows_a_band, Step { time: step, inv_kappa });
        solve_columns(&u, &mut next, columns_a_stripe, Step { time: step, inv_kappa });
        std::mem::swap(&mut u.data, &mut next);
    }
    u
}

/// One semi-implicit step: its time, and 1 / kappa of the conductance.
#[derive(Clone, Copy)]
struct Step {
    time: f32,
    inv_kappa: f32,
}

/// Lines solved side by side, one per vector lane: enough to fill AVX2's lanes several
/// times over, few enough that a 320-wide image still splits into tasks for threads.
const LANES: usize = 64;

/// How many lines a task solves side by side, of `lines` in all: LANES, or 32 or 16 where
/// that spreads them more evenly over the pool's threads. Modelled as rounds of one task
/// per thread, a round as long as its widest task: 320 columns are 5 tasks of 64 (rounds
/// of 64, 64 and 64 on two threads, one idle in the last) or 10 of 32 (5 rounds of 32).
/// On one thread every choice costs the same,
/// and LANES stays. The bits do not depend on it: each line is solved on its own.
fn lanes_for(lines: usize) -> usize {
    let threads = rayon::current_num_threads();
    let cost = |lanes: usize| {
        let widths: Vec<usize> = (0..lines).step_by(lanes).map(|start| lanes.min(lines - start)).collect();
        widths.chunks(threads).map(|round| round.iter().max().copied().unwrap_or(0)).sum::<usize>()
    };
    [32, 16].into_iter().fold(LANES, |best, lanes| if cost(lanes) < cost(best) { lanes } else { best })
}

thread_local! {
    /// A pass's working arrays (the transposed band, the elimination's factors, the
    /// changes), kept by each thread from frame to frame: allocating and zeroing them
    /// for every band of every pass cost as much as a sixth of the solve.
    static SCRATCH: std::cell::RefCell<[Vec<f32>; 3]> = const { std::cell::RefCell::new([Vec::new(), Vec::new(), Vec::new()]) };
}

/// Runs `f` on this thread's three scratch arrays, each at least `len` long (their
/// contents are left from earlier passes: `solve_down` writes before it reads).
fn with_scratch<R>(len: usize, f: impl FnOnce(&mut [f32], &mut [f32], &mut [f32]) -> R) -> R {
    SCRATCH.with_borrow_mut(|[a, b, c]| {
        for v in [&mut *a, &mut *b, &mut *c] {
            if v.len() < len {
                v.resize(len, 0.0);
            }
        }
        f(&mut a[..len], &mut b[..len], &mut c[..len])
    })
}

/// The row pass, in place (on a non-empty image). Rows are solved `band_rows` at a time: each
/// band is transposed so its rows run down a block and its pixels of one column lie side by
/// side; the change and the depth are added as the result is transposed back.
fn solve_rows(u: &mut Grid<f32>, band_rows: usize, step: Step) {
    let w = u.width;
    u.data.par_chunks_mut(w * band_rows).for_each(|band| {
        let lanes = band.len() / w;
        with_scratch(w * lanes, |block, e, out| {
            transpose(band, None, lanes, w, block);
            solve_down(block, lanes, lanes, step, e, out, None);
            transpose(out, Some(block), w, lanes, band);
        })
    });
}

/// `dst[c * rows + r] = src[r * cols + c]`, plus `plus[r * cols + c]` if given (`src` and
/// `plus` are `rows` x `cols`, row-major). In 8 x 8 tiles transposed in registers where the
/// CPU has AVX2 or NEON: element by element, the writes went a cache line apart each and
/// the two transposes of a row pass cost two thirds of its solve. The sum is the one a separate
/// pass would add, in the same order (the same bits), without that pass.
fn transpose(src: &[f32], plus: Option<&[f32]>, rows: usize, cols: usize, dst: &mut [f32]) {
    transpose_at(super::simd::level(), src, plus, rows, cols, dst);
}

/// `transpose` at `level` (at most what the CPU has): 16 x 16 tiles at AVX-512, 8 x 8 at AVX2
/// and NEON.
fn transpose_at(
    level: super::simd::Level,
    src: &[f32],
    plus: Option<&[f32]>,
    rows: usize,
    cols: usize,
    dst: &mut [f32],
) {
    let (src, dst) = (&src[..rows * cols], &mut dst[..rows * cols]);
    let plus = plus.map(|p| &p[..rows * cols]);
    // The side of the whole tiles a vector kernel transposed, if one ran.
    #[cfg(target_arch = "x86_64")]
    let tile = {
        use super::simd::Level;
        debug_assert!(level <= Level::detected());
        match level {
            // SAFETY: the CPU has AVX-512 F (the level is at most what it has); the slices are
            // rows * cols long.
            Level::Avx512 => Some(unsafe { transpose_avx512(src, plus, rows, cols, dst) }),
            // SAFETY: as above, with AVX2.
            Level::Avx2 => Some(unsafe { transpose_avx2(src, plus, rows, cols, dst) }),
            Level::Baseline | Level::Neon => None,
        }
    };
    #[cfg(target_arch = "aarch64")]
    let tile = match level {
        // SAFETY: every aarch64 CPU has NEON; the slices are rows * cols long.
        super::simd::Level::Neon => Some(unsafe { transpose_neon(src, plus, rows, cols, dst) }),
        _ => None,
    };
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let tile: Option<usize> = {
        let _ = level;
        None
    };
    // What the whole tiles leave, element by element: the rows below the last of them, and
    // the columns right of it (everything where no kernel ran).
    let (whole_rows, whole_cols) = tile.map_or((0, 0), |t| (rows / t * t, cols / t * t));
    transpose_part(src, plus, (whole_rows..rows, 0..cols), rows, cols, dst);
    transpose_part(src, plus, (0..whole_rows, whole_cols..cols), rows, cols, dst);
}

/// `transpose` of the given rows and columns only, element by element: what the whole
/// tiles leave, and everything without AVX2.
fn transpose_part(
    src: &[f32],
    plus: Option<&[f32]>,
    (part_rows, part_cols): (Range<usize>, Range<usize>),
    rows: usize,
    cols: usize,
    dst: &mut [f32],
) {
    for r in part_rows {
        for c in part_cols.clone() {
            let i = r * cols + c;
            dst[c * rows + r] = plus.map_or(src[i], |p| src[i] + p[i]);
        }
    }
}

/// The side of `transpose`'s tiles at AVX2 and NEON.
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
const TILE: usize = 8;

/// `transpose` on AVX2 of every whole 8 x 8 tile, in registers (pairs interleaved, then
/// quads, then the 128-bit halves swapped); returns the tile's side (`transpose_at` does
/// the rest).
///
/// # Safety
/// The CPU has AVX2; `src`, `plus` and `dst` hold rows * cols values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn transpose_avx2(src: &[f32], plus: Option<&[f32]>, rows: usize, cols: usize, dst: &mut [f32]) -> usize {
    use std::arch::x86_64::*;
    for r0 in (0..rows / TILE * TILE).step_by(TILE) {
        for c0 in (0..cols / TILE * TILE).step_by(TILE) {
            // SAFETY: the tile's 8 rows of 8 lie within `src` and `plus` (the last element read
            // is (r0 + 7) * cols + c0 + 7 < rows * cols) and its 8 columns of 8 within `dst`;
            // loads and stores are unaligned ones.
            unsafe {
                let at = |k: usize| (r0 + k) * cols + c0;
                let r: [__m256; 8] = std::array::from_fn(|k| {
                    let x = _mm256_loadu_ps(src.as_ptr().add(at(k)));
                    plus.map_or(x, |p| _mm256_add_ps(x, _mm256_loadu_ps(p.as_ptr().add(at(k)))))
                });
                let t = [
                    _mm256_unpacklo_ps(r[0], r[1]),
                    _mm256_unpackhi_ps(r[0], r[1]),
                    _mm256_unpacklo_ps(r[2], r[3]),
                    _mm256_unpackhi_ps(r[2], r[3]),
                    _mm256_unpacklo_ps(r[4], r[5]),
                    _mm256_unpackhi_ps(r[4], r[5]),
                    _mm256_unpacklo_ps(r[6], r[7]),
                    _mm256_unpackhi_ps(r[6], r[7]),
                ];
                let q = [
                    _mm256_shuffle_ps::<0x44>(t[0], t[2]),
                    _mm256_shuffle_ps::<0xEE>(t[0], t[2]),
                    _mm256_shuffle_ps::<0x44>(t[1], t[3]),
                    _mm256_shuffle_ps::<0xEE>(t[1], t[3]),
                    _mm256_shuffle_ps::<0x44>(t[4], t[6]),
                    _mm256_shuffle_ps::<0xEE>(t[4], t[6]),
                    _mm256_shuffle_ps::<0x44>(t[5], t[7]),
                    _mm256_shuffle_ps::<0xEE>(t[5], t[7]),
                ];
                let out = dst.as_mut_ptr().add(c0 * rows + r0);
                for k in 0..4 {
                    _mm256_storeu_ps(out.add(k * rows), _mm256_permute2f128_ps::<0x20>(q[k], q[k + 4]));
                    _mm256_storeu_ps(out.add((k + 4) * rows), _mm256_permute2f128_ps::<0x31>(q[k], q[k + 4]));
                }
            }
        }
    }
    TILE
}

/// `transpose` on NEON of every whole 8 x 8 tile, as four 4 x 4 blocks transposed in
/// registers (32-bit pairs swapped, then 64-bit halves), so each column of the tile is
/// written as 32 contiguous bytes; returns the tile's side (`transpose_at` does the rest).
///
/// # Safety
/// The CPU has NEON (every aarch64 CPU does); `src`, `plus` and `dst` hold rows * cols
/// values.
#[cfg(target_arch = "aarch64")]
#[target_feature(enable = "neon")]
unsafe fn transpose_neon(src: &[f32], plus: Option<&[f32]>, rows: usize, cols: usize, dst: &mut [f32]) -> usize {
    use std::arch::aarch64::*;
    for r0 in (0..rows / TILE * TILE).step_by(TILE) {
        for c0 in (0..cols / TILE * TILE).step_by(TILE) {
            for (br, bc) in [(0, 0), (0, 4), (4, 0), (4, 4)] {
                // SAFETY: the block's 4 rows of 4 lie within `src` and `plus` (the last
                // element read is (r0 + 7) * cols + c0 + 7 < rows * cols) and its 4 columns of
                // 4 within `dst`; loads and stores are unaligned ones.
                unsafe {
                    let at = |k: usize| (r0 + br + k) * cols + c0 + bc;
                    let r: [float32x4_t; 4] = std::array::from_fn(|k| {
                        let x = vld1q_f32(src.as_ptr().add(at(k)));
                        plus.map_or(x, |p| vaddq_f32(x, vld1q_f32(p.as_ptr().add(at(k)))))
                    });
                    // t0 = r0[0] r1[0] r0[2] r1[2], t1 = r0[1] r1[1] r0[3] r1[3], t2 and t3
                    // the same of rows 2 and 3; then the 64-bit halves of t0 and t2 (t1 and
                    // t3) make columns 0 and 2 (1 and 3).
                    let (t0, t1) = (vtrn1q_f32(r[0], r[1]), vtrn2q_f32(r[0], r[1]));
                    let (t2, t3) = (vtrn1q_f32(r[2], r[3]), vtrn2q_f32(r[2], r[3]));
                    let halves = |a: float32x4_t, b: float32x4_t| {
                        let (a, b) = (vreinterpretq_f64_f32(a), vreinterpretq_f64_f32(b));
                        (vreinterpretq_f32_f64(vtrn1q_f64(a, b)), vreinterpretq_f32_f64(vtrn2q_f64(a, b)))
                    };
                    let ((c0v, c2v), (c1v, c3v)) = (halves(t0, t2), halves(t1, t3));
                    let out = dst.as_mut_ptr().add((c0 + bc) * rows + r0 + br);
                    for (k, column) in [c0v, c1v, c2v, c3v].into_iter().enumerate() {
                        vst1q_f32(out.add(k * rows), column);
                    }
                }
            }
        }
    }
    TILE
}

/// The side of `transpose_avx512`'s tiles.
#[cfg(target_arch = "x86_64")]
const WIDE_TILE: usize = 16;

/// `transpose` on AVX-512 of every whole 16 x 16 tile, in registers (pairs interleaved,
/// then quads, then the 128-bit quarters in two steps): 64 shuffles for 256 values where
/// AVX2's 8 x 8 tiles take 32 for 64, and the shuffle port bounds them. Returns the tile's
/// side (`transpose_at` does the rest).
///
/// # Safety
/// The CPU has AVX-512 F; `src`, `plus` and `dst` hold rows * cols values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn transpose_avx512(src: &[f32], plus: Option<&[f32]>, rows: usize, cols: usize, dst: &mut [f32]) -> usize {
    use std::arch::x86_64::*;
    for r0 in (0..rows / WIDE_TILE * WIDE_TILE).step_by(WIDE_TILE) {
        for c0 in (0..cols / WIDE_TILE * WIDE_TILE).step_by(WIDE_TILE) {
            // SAFETY: the tile's 16 rows of 16 lie within `src` and `plus` (the last element
            // read is (r0 + 15) * cols + c0 + 15 < rows * cols) and its 16 columns of 16
            // within `dst`; loads and stores are unaligned ones.
            unsafe {
                let at = |k: usize| (r0 + k) * cols + c0;
                // Row k: a[k][0..16], in four 128-bit quarters of four columns each.
                let r: [__m512; 16] = std::array::from_fn(|k| {
                    let x = _mm512_loadu_ps(src.as_ptr().add(at(k)));
                    plus.map_or(x, |p| _mm512_add_ps(x, _mm512_loadu_ps(p.as_ptr().add(at(k)))))
                });
                // Rows 2k and 2k + 1 interleaved: quarter j of t[2k] holds columns 4j and
                // 4j + 1 of both, of t[2k + 1] columns 4j + 2 and 4j + 3.
                let t: [__m512; 16] = std::array::from_fn(|i| {
                    let (a, b) = (r[i & !1], r[i | 1]);
                    if i % 2 == 0 { _mm512_unpacklo_ps(a, b) } else { _mm512_unpackhi_ps(a, b) }
                });
                // Quarter j of u[4m + c]: column 4j + c of rows 4m ..= 4m + 3.
                let u: [__m512; 16] = std::array::from_fn(|i| {
                    let (m4, c) = (i & !3, i & 3);
                    let (a, b) = (t[m4 + c / 2], t[m4 + c / 2 + 2]);
                    if c % 2 == 0 { _mm512_shuffle_ps::<0x44>(a, b) } else { _mm512_shuffle_ps::<0xEE>(a, b) }
                });
                let out = dst.as_mut_ptr().add(c0 * rows + r0);
                for c in 0..4 {
                    // Column 4j + c is quarter j of u[c], u[4 + c], u[8 + c] and u[12 + c].
                    let (a, b, p, q) = (u[c], u[4 + c], u[8 + c], u[12 + c]);
                    let (ab01, ab23) = (_mm512_shuffle_f32x4::<0x44>(a, b), _mm512_shuffle_f32x4::<0xEE>(a, b));
                    let (pq01, pq23) = (_mm512_shuffle_f32x4::<0x44>(p, q), _mm512_shuffle_f32x4::<0xEE>(p, q));
                    let columns = [
                        _mm512_shuffle_f32x4::<0x88>(ab01, pq01),
                        _mm512_shuffle_f32x4::<0xDD>(ab01, pq01),
                        _mm512_shuffle_f32x4::<0x88>(ab23, pq23),
                        _mm512_shuffle_f32x4::<0xDD>(ab23, pq23),
                    ];
                    for (j, column) in columns.into_iter().enumerate() {
                        _mm512_storeu_ps(out.add((4 * j + c) * rows), column);
                    }
                }
            }
        }
    }
    WIDE_TILE
}

/// The column pass from `u` (non-empty) into `next`'s values, whatever they were: stripes
/// of `stripe` columns, read where they lie, each written by the task that solved it. Every
/// value is written, so none is set beforehand.
fn solve_columns(u: &Grid<f32>, next: &mut Vec<f32>, stripe: usize, step: Step) {
    let (w, h) = (u.width, u.height);
    next.clear();
    next.reserve(w * h);
    let image = Stripe { at: next.as_mut_ptr(), stride: w };
    (0..w.div_ceil(stripe)).into_par_iter().for_each(|k| {
        let x0 = k * stripe;
        let lanes = stripe.min(w - x0);
        with_scratch(h * lanes, |_, e, out| {
            // SAFETY: `next` has room for w * h values and outlives the pass; this task
            // alone writes columns x0..x0 + lanes of its h rows (the stripes are disjoint),
            // and nothing reads `next` until the pass is over.
            let into = unsafe { image.at_column(x0) };
            solve_down(&u.data[x0..], w, lanes, step, e, out, Some(into));
        })
    });
    // SAFETY: the stripes cover every column of every row, so all w * h values are written.
    unsafe { next.set_len(w * h) };
}

/// Where the column pass writes its depths: element i of lane k at `at + i * stride + k`.
/// `solve_columns` makes one for its whole output image and hands each task the stripe
/// from its first column (`at_column`); the solve writes through it unchecked.
#[derive(Clone, Copy)]
struct Stripe {
    at: *mut f32,
    stride: usize,
}

// SAFETY: shared only by `solve_columns`' tasks, which write disjoint columns.
unsafe impl Sync for Stripe {}

impl Stripe {
    /// The stripe from column `x0` on.
    ///
    /// # Safety
    /// The solve handed the stripe writes every row of its lanes from column `x0` on: they
    /// lie within the image, and no other thread touches them during the pass.
    unsafe fn at_column(self, x0: usize) -> Stripe {
        // SAFETY: as the caller promises.
        Stripe { at: unsafe { self.at.add(x0) }, ..self }
    }
}

super::widest_simd! {
    /// Solves `lanes` lines side by side, each running down: element i of lane k is
    /// `src[i * stride + k]` (`e` and `out` are the elimination's scratch). Without `into`,
    /// its change is left in `out[i * lanes + k]`, and the caller adds the depth as it
    /// writes the result where it goes; with it, the back substitution adds the depth and
    /// writes there itself, one pass over the lines fewer.
    fn solve_down(src: &[f32], stride: usize, lanes: usize, step: Step, e: &mut [f32], out: &mut [f32], into: Option<Stripe>) = solve_down_portable
}

/// The Thomas algorithm, lane by lane as `solve_line` does it for one line, in the
/// same order of operations, so the two agree bit for bit.
#[inline(always)]
fn solve_down_portable(
    src: &[f32],
    stride: usize,
    lanes: usize,
    step: Step,
    e: &mut [f32],
    out: &mut [f32],
    into: Option<Stripe>,
) {
    // Lane counts known when compiled: a full band's and the last band's of the usual
    // image sizes (240 and 480 rows leave 48 and 32). Their per-lane loops are then whole
    // vectors kept in registers, not loops over arrays on the stack.
    match lanes {
        LANES => solve_lanes::<LANES>(src, stride, lanes, step, e, out, into),
        48 => solve_lanes::<48>(src, stride, lanes, step, e, out, into),
        32 => solve_lanes::<32>(src, stride, lanes, step, e, out, into),
        16 => solve_lanes::<16>(src, stride, lanes, step, e, out, into),
        _ => solve_lanes::<0>(src, stride, lanes, step, e, out, into),
    }
}

/// `solve_down` on FIXED lanes, or on `lanes` where FIXED is 0.
#[inline(always)]
fn solve_lanes<const FIXED: usize>(
    src: &[f32],
    stride: usize,
    lanes: usize,
    step: Step,
    e: &mut [f32],
    out: &mut [f32],
    into: Option<Stripe>,
) {
    let lanes = if FIXED > 0 { FIXED } else { lanes };
    // Lets the compiler drop the bounds checks of the per-lane arrays.
    assert!(lanes <= LANES && e.len() == out.len());
    let len = out.len() / lanes;
    // Per lane: the coupling and flux to the element above and below, and the
    // elimination's last factor and change.
    let (mut above, mut below) = ([0.0f32; LANES], [0.0f32; LANES]);
    let (mut flux_above, mut flux_below) = ([0.0f32; LANES], [0.0f32; LANES]);
    let (mut e_prev, mut out_prev) = ([0.0f32; LANES], [0.0f32; LANES]);
    for i in 0..len {
        let z = &src[i * stride..i * stride + lanes];
        if i + 1 < len {
            let q = &src[(i + 1) * stride..(i + 1) * stride + lanes];
            for k in 0..lanes {
                below[k] = coupling(z[k], q[k], step.time, step.inv_kappa);
                flux_below[k] = below[k] * (q[k] - z[k]);
            }
        } else {
            below = [0.0; LANES];
            flux_below = [0.0; LANES];
        }
        let (e_row, out_row) = (&mut e[i * lanes..(i + 1) * lanes], &mut out[i * lanes..(i + 1) * lanes]);
        for k in 0..lanes {
            let m = 1.0 / (1.0 + above[k] + below[k] - above[k] * e_prev[k]);
            e_prev[k] = below[k] * m;
            out_prev[k] = (flux_below[k] - flux_above[k] + above[k] * out_prev[k]) * m;
            e_row[k] = e_prev[k];
            out_row[k] = out_prev[k];
        }
        std::mem::swap(&mut above, &mut below);
        std::mem::swap(&mut flux_above, &mut flux_below);
    }
    // Back substitution, each element's change kept for the one above it. The row pass
    // leaves the changes in `out` (it adds the depth as it transposes them back); the
    // column pass adds the depth and writes the result out here, one pass fewer.
    let mut change = [0.0f32; LANES];
    for i in (0..len).rev() {
        let (out_row, e_row) = (&mut out[i * lanes..(i + 1) * lanes], &e[i * lanes..(i + 1) * lanes]);
        for k in 0..lanes {
            change[k] = if i + 1 < len { out_row[k] + e_row[k] * change[k] } else { out_row[k] };
        }
        match into {
            None => out_row.copy_from_slice(&change[..lanes]),
            Some(into) => {
                let z = &src[i * stride..i * stride + lanes];
                for k in 0..lanes {
                    // SAFETY: `into` is the solve's own stripe of len rows of lanes values
                    // (`Stripe`), as the column pass hands it over.
                    unsafe { into.at.add(i * into.stride + k).write(change[k] + z[k]) };
                }
            }
        }
    }
}

/// The oracle: one line's implicit solve by the Thomas algorithm, element i at
/// `data[start + i * stride]`, in place; the fast loop is this, lane by lane, bit for bit.
/// It solves for the change of depth, not the depth: the right-hand side is then the
/// explicit fluxes, exactly 0 on a constant, and the millimetres that move keep their bits.
pub fn solve_line(data: &mut [f32], start: usize, stride: usize, len: usize, step: f32, inv_kappa: f32) {
    let at = |i: usize| start + i * stride;
    let (mut e, mut change) = (vec![0.0f32; len], vec![0.0f32; len]);
    let (mut above, mut flux_above, mut e_prev, mut change_prev) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for i in 0..len {
        let z = data[at(i)];
        let (mut below, mut flux_below) = (0.0f32, 0.0f32);
        if i + 1 < len {
            let q = data[at(i + 1)];
            below = coupling(z, q, step, inv_kappa);
            flux_below = below * (q - z);
        }
        let m = 1.0 / (1.0 + above + below - above * e_prev);
        e_prev = below * m;
        change_prev = (flux_below - flux_above + above * change_prev) * m;
        e[i] = e_prev;
        change[i] = change_prev;
        above = below;
        flux_above = flux_below;
    }
    let mut next = change_prev;
    for i in (0..len.saturating_sub(1)).rev() {
        next = change[i] + e[i] * next;
        change[i] = next;
    }
    for (i, c) in change.into_iter().enumerate() {
        data[at(i)] += c;
    }
}

/// The same system solved as shaders/diffusion.wgsl solves it, one invocation at a time:
/// cyclic reduction over rows 1..=2^m - 1 (row r is element r - 1, rows past the line
/// are x = 0). The order of operations differs from the Thomas algorithm's, so the two
/// agree to rounding of the change (the test holds them within 2 ulps of the depth).
pub fn cyclic_reduction(data: &mut [f32], start: usize, stride: usize, len: usize, step: f32, inv_kappa: f32) {
    if len == 0 {
        return;
    }
    let at = |r: usize| start + (r - 1) * stride;
    let rows = (1usize << (usize::BITS - len.leading_zeros())) - 1;
    let (mut sub, mut diag, mut sup, mut rhs) =
        (vec![0.0f32; rows + 1], vec![1.0f32; rows + 1], vec![0.0f32; rows + 1], vec![0.0f32; rows + 1]);
    for r in 1..=len {
        let z = data[at(r)];
        let (mut above, mut below, mut flux_above, mut flux_below) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        if r > 1 {
            let o = data[at(r - 1)];
            above = coupling(o, z, step, inv_kappa);
            flux_above = above * (z - o);
        }
        if r < len {
            let q = data[at(r + 1)];
            below = coupling(z, q, step, inv_kappa);
            flux_below = below * (q - z);
        }
        (sub[r], diag[r], sup[r], rhs[r]) = (-above, 1.0 + above + below, -below, flux_below - flux_above);
    }
    let mut s = 1;
    while 2 * s <= rows {
        for r in (2 * s..=rows).step_by(2 * s) {
            let alpha = -sub[r] / diag[r - s];
            let gamma = -sup[r] / diag[r + s];
            diag[r] = diag[r] + alpha * sup[r - s] + gamma * sub[r + s];
            rhs[r] = rhs[r] + alpha * rhs[r - s] + gamma * rhs[r + s];
            sub[r] = alpha * sub[r - s];
            sup[r] = gamma * sup[r + s];
        }
        s *= 2;
    }
    s = rows.div_ceil(2);
    loop {
        for r in (s..=rows).step_by(2 * s) {
            let mut x = rhs[r];
            if r > s {
                x -= sub[r] * rhs[r - s];
            }
            if r + s <= rows {
                x -= sup[r] * rhs[r + s];
            }
            rhs[r] = x / diag[r];
        }
        if s == 1 {
            break;
        }
        s /= 2;
    }
    for r in 1..=len {
        data[at(r)] += rhs[r];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cyclic_reduction_solves_the_thomas_system() {
        // Lines of every length from 1 to 130 (2^m - 1 and the lengths either side, where
        // the padding changes), and 640 and 1023, of a noisy ramp with a step and holes.
        let line = |len: usize| -> Vec<f32> {
            (0..len)
                .map(|i| {
                    let z = 1.0 + 0.004 * i as f32 + if i > len / 2 { 0.15 } else { 0.0 };
                    if i % 37 == 5 { 0.0 } else { z + 0.002 * ((i * 7919 % 101) as f32 / 101.0 - 0.5) }
                })
                .collect()
        };
        let ulp = f32::EPSILON;
        for len in (1..=130).chain([640, 1023]) {
            let depth = line(len);
            let (mut thomas, mut cyclic) = (depth.clone(), depth.clone());
            solve_line(&mut thomas, 0, 1, len, 3.0, 1.0 / 0.0335);
            cyclic_reduction(&mut cyclic, 0, 1, len, 3.0, 1.0 / 0.0335);
            for i in 0..len {
                assert!((thomas[i] - cyclic[i]).abs() <= 2.0 * ulp * depth[i], "length {len}, element {i}");
                assert_eq!(cyclic[i] == 0.0, depth[i] == 0.0, "length {len}, element {i}: holes stay holes");
            }
            if len > 40 {
                assert_ne!(cyclic, depth, "length {len}: the solve moved the depth");
            }
        }
    }

    #[test]
    fn fast_diffusion_is_the_line_oracle_bit_for_bit() {
        // A noisy slanted plane with a step, holes and a hole touching the border. The sizes
        // leave both passes a partial band of lanes: 33 and 2 (counts not known when
        // compiled), and each of 16, 32 and 48 (known).
        for (w, h) in [(97, 130), (80, 176), (96, 112)] {
            diffusion_matches_the_oracle(w, h);
        }
    }

    fn diffusion_matches_the_oracle(w: usize, h: usize) {
        let mut data: Vec<f32> = (0..w * h)
            .map(|i| {
                let (u, v) = ((i % w) as f32, (i / w) as f32);
                let step = if u > 50.0 { 0.15 } else { 0.0 };
                1.0 + 0.004 * v + step + 0.002 * ((i * 7919 % 101) as f32 / 101.0 - 0.5)
            })
            .collect();
        for (i, z) in data.iter_mut().enumerate() {
            if i % 131 == 0 || (i % w < 3 && i / w < 4) {
                *z = 0.0;
            }
        }
        let depth = Grid { width: w, height: h, data };
        let (kappa, time) = (0.0335f32, 12.0f32);
        for steps in 1..=3 {
            let mut oracle = depth.data.clone();
            let step = time / steps as f32;
            for _ in 0..steps {
                for v in 0..h {
                    solve_line(&mut oracle, v * w, 1, w, step, 1.0 / kappa);
                }
                for u in 0..w {
                    solve_line(&mut oracle, u, w, h, step, 1.0 / kappa);
                }
            }
            // On pools of 1, 2 and 16 threads: bands and stripes of 64, 32 and 16 lines.
            for threads in [1, 2, 16] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let fast = pool.install(|| diffuse(&depth, time, steps, kappa));
                for i in 0..w * h {
                    let bits = (fast.data[i].to_bits(), oracle[i].to_bits());
                    assert_eq!(bits.0, bits.1, "{w}x{h}, {steps} steps, {threads} threads, pixel {i}");
                }
            }
            assert_ne!(oracle, depth.data, "the steps moved the depth");
        }
    }

    #[test]
    fn lines_split_into_tasks_that_even_out_the_threads() {
        let on = |threads: usize, lines: usize| {
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| lanes_for(lines))
        };
        // One thread: always the widest. Two: 320 columns as 10 tasks of 32, not 5 of 64;
        // 640 and 240 split evenly at 64 already. Sixteen: 640 columns as 40 tasks of 16.
        assert!((1..700).all(|lines| on(1, lines) == LANES));
        assert_eq!([on(2, 320), on(2, 640), on(2, 240), on(16, 640)], [32, LANES, LANES, 16]);
    }

    #[test]
    fn transpose_is_the_element_by_element_one() {
        use crate::extract::cpu::simd::Level;
        // Whole tiles of 8 and 16 and partial ones on either side, at every level the CPU has.
        let sizes = [(8, 8), (16, 16), (64, 97), (2, 97), (17, 9), (1, 1), (48, 320), (320, 32), (33, 40)];
        let levels: Vec<Level> = Level::ALL.iter().copied().filter(|&l| l <= Level::detected()).collect();
        for level in levels {
            for (rows, cols) in sizes {
                let src: Vec<f32> = (0..rows * cols).map(|i| i as f32).collect();
                let mut dst = vec![f32::NAN; rows * cols];
                let plus: Vec<f32> = (0..rows * cols).map(|i| (i * 7 % 13) as f32 * 0.25).collect();
                let mut summed = vec![f32::NAN; rows * cols];
                transpose_at(level, &src, None, rows, cols, &mut dst);
                transpose_at(level, &src, Some(&plus), rows, cols, &mut summed);
                for r in 0..rows {
                    for c in 0..cols {
                        let i = r * cols + c;
                        assert_eq!(dst[c * rows + r], src[i], "{level:?}, {rows} x {cols}, ({r}, {c})");
                        assert_eq!(
                            summed[c * rows + r],
                            src[i] + plus[i],
                            "{level:?}, {rows} x {cols}, ({r}, {c}), summed"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn conductance_matches_exp() {
        for i in 0..2000 {
            let d = (i as f32 - 1000.0) * 1e-4;
            let exact = (-(d / 0.0335f32).powi(2)).exp();
            let approx = conductance(d, 1.0 / 0.0335);
            assert!((approx - exact).abs() <= 5e-6 * exact + 1e-30, "d {d}: {approx} vs {exact}");
        }
        assert!(conductance(10.0, 1.0 / 0.0335) < 1e-30);
    }
}
