//! Batched RANSAC plane fits for all of a frame's regions at once: the CPU twin of
//! shaders/ransac.wgsl, then a least-squares refit on the inliers.
//!
//! Points of every region sit in one flat array with a range per region. Hypothesis h
//! of region r samples its three points with an integer hash; `ScoringBatch` gathers,
//! once for either twin, every hypothesis's plane and each region's strided scoring
//! subset, which the CPU scores here and the GPU twin uploads and scores in one dispatch.

use std::ops::Range;

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rayon::prelude::*;

use super::simd::Level;

/// At most this many points (evenly strided) score each hypothesis.
pub const MAX_SCORE_POINTS: usize = 2048;

/// All regions' camera-frame points, region r being `points[ranges[r]]`.
#[derive(Clone, Debug, Default)]
pub struct PointBatch {
    pub points: Vec<[f32; 3]>,
    pub ranges: Vec<Range<usize>>,
}

/// A fitted plane n . p + d = 0 (n faces the camera, so d > 0) and its support.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFit {
    pub normal: Vector3<f64>,
    pub offset: f64,
    /// Points within the inlier distance of the refitted plane.
    pub inliers: usize,
    pub points: usize,
    /// RMS distance of the inliers to the plane, m.
    pub rms: f64,
}

impl PlaneFit {
    pub fn inlier_ratio(&self) -> f64 {
        self.inliers as f64 / self.points.max(1) as f64
    }

    /// Distance of a point to the plane, m.
    #[inline]
    pub fn distance(&self, p: &[f32; 3]) -> f64 {
        (self.normal.dot(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)) + self.offset).abs()
    }

    pub fn normal_f32(&self) -> [f32; 3] {
        [self.normal.x as f32, self.normal.y as f32, self.normal.z as f32]
    }
}

/// lowbias32 (Chris Wellons): a well-mixed 32-bit hash, plain u32 arithmetic that WGSL has too.
#[inline]
pub fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// Index (within its region of `n` points) of sample j of hypothesis h of region r.
#[inline]
pub fn sample_index(region: u32, hypothesis: u32, j: u32, n: u32) -> u32 {
    hash(region.wrapping_mul(0x9e37_79b9) ^ hash(hypothesis * 3 + j)) % n
}

/// Three points closer to collinear than this (the sine of the angle at the first) give
/// no plane. The cross product of nearly parallel edges is mostly rounding, and rounding
/// differs between the twins (a GPU may fuse multiply-adds): an absolute floor let an
/// NVIDIA GPU score a plane where the CPU saw none.
pub const MIN_SAMPLE_SINE: f32 = 1e-3;

/// Plane through three points as (unit normal, offset), or None if they are (nearly) collinear.
#[inline]
pub fn plane_through(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Option<([f32; 3], f32)> {
    let (e1, e2) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let edges =
        ((e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]) * (e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2])).sqrt();
    if !(len > MIN_SAMPLE_SINE * edges) {
        return None;
    }
    let n = [n[0] / len, n[1] / len, n[2] / len];
    Some((n, -(n[0] * a[0] + n[1] * a[1] + n[2] * a[2])))
}

/// The smallest stride that takes at most `max` of `len` points (every stride-th): how
/// the scoring, the first fits, a cut's stray count and the plane covariances sample a
/// large region's points, which lie on a regular pixel grid.
#[inline]
pub fn sample_stride(len: usize, max: usize) -> usize {
    len.div_ceil(max.max(1)).max(1)
}

/// `f` on every stride-th of `items`, in order. An index loop: `step_by`'s fold was not
/// inlined into the loops that sample, and took half as long again as they did.
#[inline(always)]
pub fn for_each_strided<T>(items: &[T], stride: usize, mut f: impl FnMut(&T)) {
    let mut i = 0;
    while let Some(item) = items.get(i) {
        f(item);
        i += stride;
    }
}

/// Scoring stride for a region of n points.
#[inline]
pub fn score_stride(n: usize) -> usize {
    sample_stride(n, MAX_SCORE_POINTS)
}

/// What each twin scores, gathered once: every region's scoring subset (every stride-th
/// point) one region after another, as planes of x, y and z so that each hypothesis
/// scores with one contiguous, vectorised loop, and every hypothesis's plane. The GPU
/// twin uploads exactly this: a region's subset is at most `MAX_SCORE_POINTS` points, its
/// samples are drawn from all of them.
pub struct ScoringBatch {
    /// x of every subset point, then y, then z.
    pub coords: Vec<f32>,
    /// Each region's (first point, point count) in the subsets.
    pub ranges: Vec<[u32; 2]>,
    /// (normal, offset) of hypothesis h of region r at r * hypotheses + h; all zero for none.
    pub planes: Vec<[f32; 4]>,
}

impl ScoringBatch {
    pub fn new(batch: &PointBatch, hypotheses: u32) -> ScoringBatch {
        let counts: Vec<usize> = batch.ranges.iter().map(|r| r.len().div_ceil(score_stride(r.len()))).collect();
        let total: usize = counts.iter().sum();
        let mut coords = vec![0.0f32; 3 * total];
        let (mut ranges, mut first) = (Vec::with_capacity(counts.len()), 0);
        // Each region's three stretches of the planes, handed out in order, filled side by side.
        let (x, yz) = coords.split_at_mut(total);
        let (y, z) = yz.split_at_mut(total);
        let (mut x, mut y, mut z) = (x, y, z);
        let mut work = Vec::with_capacity(counts.len());
        for (range, &count) in batch.ranges.iter().zip(&counts) {
            let (xr, xs) = std::mem::take(&mut x).split_at_mut(count);
            let (yr, ys) = std::mem::take(&mut y).split_at_mut(count);
            let (zr, zs) = std::mem::take(&mut z).split_at_mut(count);
            (x, y, z) = (xs, ys, zs);
            work.push((&batch.points[range.clone()], xr, yr, zr));
            ranges.push([first as u32, count as u32]);
            first += count;
        }
        work.into_par_iter().for_each(|(pts, x, y, z)| {
            // One pass over the strided points (a pass a coordinate read each point's cache
            // line three times).
            for (((x, y), z), p) in x.iter_mut().zip(y).zip(z).zip(pts.iter().step_by(score_stride(pts.len()))) {
                [*x, *y, *z] = *p;
            }
        });
        let planes = (0..batch.ranges.len() * hypotheses as usize)
            .into_par_iter()
            .map(|k| {
                let (r, h) = (k / hypotheses as usize, (k % hypotheses as usize) as u32);
                hypothesis(batch, r, h).map_or([0.0; 4], |(n, d)| [n[0], n[1], n[2], d])
            })
            .collect();
        ScoringBatch { coords, ranges, planes }
    }

    /// The subset points of region r as planes of x, y and z.
    fn subset(&self, r: usize) -> [&[f32]; 3] {
        let total = self.coords.len() / 3;
        let [first, count] = self.ranges[r].map(|v| v as usize);
        [0, 1, 2].map(|axis| &self.coords[axis * total + first..axis * total + first + count])
    }
}

/// Inlier count of every (region, hypothesis), row-major by region: the batched stage.
pub fn score_hypotheses(batch: &PointBatch, hypotheses: u32, inlier_distance: f32) -> Vec<u32> {
    let scoring = ScoringBatch::new(batch, hypotheses);
    scoring
        .planes
        .par_iter()
        .enumerate()
        .map(|(k, &[a, b, c, d])| {
            if [a, b, c] == [0.0; 3] {
                return 0;
            }
            let [x, y, z] = scoring.subset(k / hypotheses as usize);
            count_inliers(x, y, z, [a, b, c], d, inlier_distance)
        })
        .collect()
}

super::widest_simd! {
    /// Points (x[i], y[i], z[i]) within `dist` of the plane n . p + d = 0.
    fn count_inliers(x: &[f32], y: &[f32], z: &[f32], n: [f32; 3], d: f32, dist: f32) -> u32 = count_inliers_portable
}

#[inline(always)]
fn count_inliers_portable(x: &[f32], y: &[f32], z: &[f32], n: [f32; 3], d: f32, dist: f32) -> u32 {
    let len = x.len();
    let (x, y, z) = (&x[..len], &y[..len], &z[..len]);
    (0..len).map(|i| u32::from((n[0] * x[i] + n[1] * y[i] + n[2] * z[i] + d).abs() < dist)).sum()
}

/// The oracle of `score_hypotheses`: hypothesis h of region r alone, as shaders/ransac.wgsl
/// scores it (every stride-th point of the region).
pub fn score_at(batch: &PointBatch, r: usize, h: u32, inlier_distance: f32) -> u32 {
    let Some((nrm, d)) = hypothesis(batch, r, h) else { return 0 };
    let pts = &batch.points[batch.ranges[r].clone()];
    let stride = score_stride(pts.len());
    let mut inliers = 0;
    for j in 0..pts.len().div_ceil(stride) {
        if near_plane(&pts[j * stride], nrm, d, inlier_distance) {
            inliers += 1;
        }
    }
    inliers
}

/// The plane of the best hypothesis of region r (lowest index wins a tie).
pub fn best_hypothesis(batch: &PointBatch, scores: &[u32], r: usize, hypotheses: u32) -> Option<([f32; 3], f32)> {
    let row = &scores[r * hypotheses as usize..(r + 1) * hypotheses as usize];
    let (h, &best) = row.iter().enumerate().max_by_key(|&(h, &s)| (s, std::cmp::Reverse(h)))?;
    if best == 0 {
        return None;
    }
    hypothesis(batch, r, h as u32)
}

/// The plane of hypothesis h of region r: through its three sampled points; None for a
/// region of under three points or collinear samples.
pub fn hypothesis(batch: &PointBatch, r: usize, h: u32) -> Option<([f32; 3], f32)> {
    let pts = &batch.points[batch.ranges[r].clone()];
    let n = pts.len() as u32;
    if n < 3 {
        return None;
    }
    let s = |j| pts[sample_index(r as u32, h, j, n) as usize];
    plane_through(s(0), s(1), s(2))
}

/// Least-squares plane through the points within `dist` of (n, d), then its support.
/// One pass gathers the inliers' moments, taken about the first inlier so that f64 keeps
/// the millimetres at metres of range; a second counts the support. Nothing is allocated:
/// a frame refits every region three or four times. One part of `refit_parts`.
pub fn refit(points: &[[f32; 3]], n: [f32; 3], d: f32, dist: f32) -> Option<PlaneFit> {
    refit_parts(std::slice::from_ref(&points), n, d, dist)
}

/// `refit` of one region's points cut into parts (in order), each part's passes a task
/// of its own: a 640x480 floor's hundred thousand points were one thread's work while the
/// others waited. Each part's sums are added in order, so the plane does not depend on
/// the threads; with one part it is `refit`'s, bit for bit, and nothing is allocated.
pub fn refit_parts<P: AsRef<[[f32; 3]]> + Sync>(parts: &[P], n: [f32; 3], d: f32, dist: f32) -> Option<PlaneFit> {
    let (at, first) = parts
        .iter()
        .enumerate()
        .find_map(|(i, part)| part.as_ref().iter().position(|p| near_plane(p, n, d, dist)).map(|k| (i, k)))?;
    let o = parts[at].as_ref()[first].map(f64::from);
    // From the first inlier on, as one part's pass takes them.
    let (head, tail) = (&parts[at].as_ref()[first..], &parts[at + 1..]);
    let m = match tail {
        [] => inlier_moments(head, n, d, dist, o),
        _ => {
            let (head, tail) = rayon::join(
                || inlier_moments(head, n, d, dist, o),
                || tail.par_iter().map(|part| inlier_moments(part.as_ref(), n, d, dist, o)).collect::<Vec<_>>(),
            );
            tail.into_iter().fold(head, RefitSums::plus)
        }
    };
    if m.count < 3.0 {
        return None;
    }
    let (sum, origin) = (Vector3::from(m.sum), Vector3::from(o));
    let mean = sum / m.count;
    let ss = m.products;
    let products = Matrix3::new(ss[0], ss[1], ss[2], ss[1], ss[3], ss[4], ss[2], ss[4], ss[5]);
    let cov = products - mean * sum.transpose();
    let eig = SymmetricEigen::new(cov);
    let mut normal: Vector3<f64> = eig.eigenvectors.column(eig.eigenvalues.imin()).into();
    let c = origin + mean;
    // Face the camera (at the origin).
    if normal.dot(&c) > 0.0 {
        normal = -normal;
    }
    let offset = -normal.dot(&c);
    let support_of = |part: &P| support(part.as_ref(), normal.into(), offset, dist as f64);
    let (support, square_sum) = match parts {
        [one] => support_of(one),
        _ => parts
            .par_iter()
            .map(support_of)
            .collect::<Vec<_>>()
            .into_iter()
            .fold((0, 0.0), |(n, s), (m, t)| (n + m, s + t)),
    };
    let rms = (square_sum / support.max(1) as f64).sqrt();
    let points = parts.iter().map(|part| part.as_ref().len()).sum();
    Some(PlaneFit { normal, offset, inliers: support, points, rms })
}

/// Whether p lies within `dist` of the plane (n, d), in f32: how a hypothesis scores a
/// point (`score_at`) and a refit picks its inliers.
#[inline(always)]
fn near_plane(p: &[f32; 3], n: [f32; 3], d: f32, dist: f32) -> bool {
    (n[0] * p[0] + n[1] * p[1] + n[2] * p[2] + d).abs() < dist
}

/// A refit's sums over its inliers: how many, and the sums of q and of q's six distinct
/// products (xx, xy, xz, yy, yz, zz), q being a point less the origin they are taken about.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct RefitSums {
    count: f64,
    sum: [f64; 3],
    products: [f64; 6],
}

impl RefitSums {
    fn plus(self, o: RefitSums) -> RefitSums {
        RefitSums {
            count: self.count + o.count,
            sum: std::array::from_fn(|k| self.sum[k] + o.sum[k]),
            products: std::array::from_fn(|k| self.products[k] + o.products[k]),
        }
    }
}

/// Refit's two passes go over every point of a region (a frame's refits read its points six
/// to eight times), so they take eight points at a time in AVX-512, four in AVX2 or NEON;
/// at the baseline, and for the last points, the scalar loops below. The same inliers
/// either way: only the order of the f64 sums differs.
fn inlier_moments(points: &[[f32; 3]], n: [f32; 3], d: f32, dist: f32, o: [f64; 3]) -> RefitSums {
    let (level, full, rest) = split_for_vectors(points);
    // SAFETY: each pass runs only at a level the CPU has (`simd::level()`).
    let fast = match level {
        #[cfg(target_arch = "x86_64")]
        Level::Avx512 => unsafe { avx512::inlier_moments(full, n, d, dist, o) },
        #[cfg(target_arch = "x86_64")]
        Level::Avx2 => unsafe { avx2::inlier_moments(full, n, d, dist, o) },
        #[cfg(target_arch = "aarch64")]
        Level::Neon => unsafe { neon::inlier_moments(full, n, d, dist, o) },
        _ => RefitSums::default(),
    };
    fast.plus(inlier_moments_scalar(rest, n, d, dist, o))
}

/// The points within `dist` of (n, offset), and the sum of their squared distances. A point
/// counts exactly where `PlaneFit::distance` puts it within `dist` of the plane (the same
/// operations in the same order).
pub fn support(points: &[[f32; 3]], n: [f64; 3], offset: f64, dist: f64) -> (usize, f64) {
    let (level, full, rest) = split_for_vectors(points);
    // SAFETY: each pass runs only at a level the CPU has (`simd::level()`).
    let (count, squares) = match level {
        #[cfg(target_arch = "x86_64")]
        Level::Avx512 => unsafe { avx512::support(full, n, offset, dist) },
        #[cfg(target_arch = "x86_64")]
        Level::Avx2 => unsafe { avx2::support(full, n, offset, dist) },
        #[cfg(target_arch = "aarch64")]
        Level::Neon => unsafe { neon::support(full, n, offset, dist) },
        _ => (0, 0.0),
    };
    let (more, more_squares) = support_scalar(rest, n, offset, dist);
    (count + more, squares + more_squares)
}

/// The level the refit's passes run at, and `points` split into what its vector pass
/// takes (whole steps of eight points in AVX-512, four in AVX2 or NEON, none at the
/// baseline) and the rest, for the scalar loop.
fn split_for_vectors(points: &[[f32; 3]]) -> (Level, &[[f32; 3]], &[[f32; 3]]) {
    let level = super::simd::level();
    let step = match level {
        Level::Avx512 => 8,
        Level::Avx2 | Level::Neon => 4,
        Level::Baseline => return (level, &[], points),
    };
    let (full, rest) = points.split_at(points.len() / step * step);
    (level, full, rest)
}

/// `inlier_moments`, one point after another: the oracle of the AVX2 and AVX-512 passes.
fn inlier_moments_scalar(points: &[[f32; 3]], n: [f32; 3], d: f32, dist: f32, o: [f64; 3]) -> RefitSums {
    let mut m = RefitSums::default();
    for p in points.iter().filter(|p| near_plane(p, n, d, dist)) {
        let q = [p[0] as f64 - o[0], p[1] as f64 - o[1], p[2] as f64 - o[2]];
        m.count += 1.0;
        m.sum = [m.sum[0] + q[0], m.sum[1] + q[1], m.sum[2] + q[2]];
        let ss = m.products;
        m.products = [
            ss[0] + q[0] * q[0],
            ss[1] + q[0] * q[1],
            ss[2] + q[0] * q[2],
            ss[3] + q[1] * q[1],
            ss[4] + q[1] * q[2],
            ss[5] + q[2] * q[2],
        ];
    }
    m
}

/// `support`, one point after another: the oracle of the AVX2 and AVX-512 passes.
fn support_scalar(points: &[[f32; 3]], n: [f64; 3], offset: f64, dist: f64) -> (usize, f64) {
    let (mut count, mut squares) = (0, 0.0);
    for p in points {
        let e = (n[0] * p[0] as f64 + n[1] * p[1] as f64 + n[2] * p[2] as f64 + offset).abs();
        if e < dist {
            count += 1;
            squares += e * e;
        }
    }
    (count, squares)
}

/// Refit's passes on four points at a time, each lane summing its own points. The points
/// come as x y z triples: three loads hold four of them, and two blends and a permute
/// give each coordinate's four values. The distances are the scalar loops' operations in
/// the same order (no fused multiply-add), so a point is an inlier on both or on neither.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use super::RefitSums;
    use crate::extract::cpu::simd::{four_points, lane_sum};

    /// `inlier_moments` of a multiple of four points.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn inlier_moments(points: &[[f32; 3]], n: [f32; 3], d: f32, dist: f32, o: [f64; 3]) -> RefitSums {
        let [nx, ny, nz, d, dist] = [n[0], n[1], n[2], d, dist].map(|v| _mm_set1_ps(v));
        let (abs, one) = (_mm_castsi128_ps(_mm_set1_epi32(i32::MAX)), _mm_set1_ps(1.0));
        let [ox, oy, oz] = o.map(|v| _mm256_set1_pd(v));
        let mut acc = [_mm256_setzero_pd(); 10];
        for quad in points.chunks_exact(4) {
            // SAFETY: a chunk of 4 points is 12 floats.
            let [x, y, z] = unsafe { four_points(quad.as_ptr().cast()) };
            let e = _mm_and_ps(
                _mm_add_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(nx, x), _mm_mul_ps(ny, y)), _mm_mul_ps(nz, z)), d),
                abs,
            );
            // 1 for an inlier, 0 for an outlier: an outlier adds zeros.
            let w = _mm256_cvtps_pd(_mm_and_ps(_mm_cmplt_ps(e, dist), one));
            let qx = _mm256_mul_pd(_mm256_sub_pd(_mm256_cvtps_pd(x), ox), w);
            let qy = _mm256_mul_pd(_mm256_sub_pd(_mm256_cvtps_pd(y), oy), w);
            let qz = _mm256_mul_pd(_mm256_sub_pd(_mm256_cvtps_pd(z), oz), w);
            acc[0] = _mm256_add_pd(acc[0], w);
            acc[1] = _mm256_add_pd(acc[1], qx);
            acc[2] = _mm256_add_pd(acc[2], qy);
            acc[3] = _mm256_add_pd(acc[3], qz);
            acc[4] = _mm256_fmadd_pd(qx, qx, acc[4]);
            acc[5] = _mm256_fmadd_pd(qx, qy, acc[5]);
            acc[6] = _mm256_fmadd_pd(qx, qz, acc[6]);
            acc[7] = _mm256_fmadd_pd(qy, qy, acc[7]);
            acc[8] = _mm256_fmadd_pd(qy, qz, acc[8]);
            acc[9] = _mm256_fmadd_pd(qz, qz, acc[9]);
        }
        let t = acc.map(|v| lane_sum(v));
        RefitSums { count: t[0], sum: [t[1], t[2], t[3]], products: [t[4], t[5], t[6], t[7], t[8], t[9]] }
    }

    /// `support` of a multiple of four points.
    ///
    /// # Safety
    /// The CPU has AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn support(points: &[[f32; 3]], n: [f64; 3], offset: f64, dist: f64) -> (usize, f64) {
        let [nx, ny, nz, offset, dist] = [n[0], n[1], n[2], offset, dist].map(|v| _mm256_set1_pd(v));
        let abs = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
        let (mut count, mut squares) = (_mm256_setzero_si256(), _mm256_setzero_pd());
        for quad in points.chunks_exact(4) {
            // SAFETY: a chunk of 4 points is 12 floats.
            let [x, y, z] = unsafe { four_points(quad.as_ptr().cast()) }.map(|v| _mm256_cvtps_pd(v));
            let r = _mm256_add_pd(
                _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, x), _mm256_mul_pd(ny, y)), _mm256_mul_pd(nz, z)),
                offset,
            );
            let e = _mm256_and_pd(r, abs);
            let inlier = _mm256_cmp_pd::<_CMP_LT_OQ>(e, dist);
            // An inlier's mask is -1 as an integer: subtracting it counts one.
            count = _mm256_sub_epi64(count, _mm256_castpd_si256(inlier));
            squares = _mm256_add_pd(squares, _mm256_and_pd(_mm256_mul_pd(e, e), inlier));
        }
        let mut c = [0i64; 4];
        // SAFETY: stores 4 i64 into a local array of 4.
        unsafe { _mm256_storeu_si256(c.as_mut_ptr().cast(), count) };
        (c.iter().sum::<i64>() as usize, lane_sum(squares))
    }
}

/// Refit's passes on eight points at a time, as `avx2` does them on four: each lane sums
/// its own points; two permutes across two registers pick each coordinate's eight values
/// out of the 24 floats of eight x y z triples; the distances are the scalar loops'
/// operations in the same order (no fused multiply-add).
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use std::arch::x86_64::*;

    use super::RefitSums;
    use crate::extract::cpu::simd::{eight_points, lane_sum8};

    /// `inlier_moments` of a multiple of eight points.
    ///
    /// # Safety
    /// The CPU has AVX-512 F and VL.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(super) unsafe fn inlier_moments(points: &[[f32; 3]], n: [f32; 3], d: f32, dist: f32, o: [f64; 3]) -> RefitSums {
        let [nx, ny, nz, d, dist] = [n[0], n[1], n[2], d, dist].map(|v| _mm256_set1_ps(v));
        let (abs, one) = (_mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX)), _mm256_set1_ps(1.0));
        let [ox, oy, oz] = o.map(|v| _mm512_set1_pd(v));
        let mut acc = [_mm512_setzero_pd(); 10];
        for eight in points.chunks_exact(8) {
            // SAFETY: a chunk of 8 points is 24 floats.
            let [x, y, z] = unsafe { eight_points(eight.as_ptr().cast()) };
            let e = _mm256_and_ps(
                _mm256_add_ps(
                    _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(nx, x), _mm256_mul_ps(ny, y)), _mm256_mul_ps(nz, z)),
                    d,
                ),
                abs,
            );
            // 1 for an inlier, 0 for an outlier: an outlier adds zeros.
            let w = _mm512_cvtps_pd(_mm256_and_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(e, dist), one));
            let qx = _mm512_mul_pd(_mm512_sub_pd(_mm512_cvtps_pd(x), ox), w);
            let qy = _mm512_mul_pd(_mm512_sub_pd(_mm512_cvtps_pd(y), oy), w);
            let qz = _mm512_mul_pd(_mm512_sub_pd(_mm512_cvtps_pd(z), oz), w);
            acc[0] = _mm512_add_pd(acc[0], w);
            acc[1] = _mm512_add_pd(acc[1], qx);
            acc[2] = _mm512_add_pd(acc[2], qy);
            acc[3] = _mm512_add_pd(acc[3], qz);
            acc[4] = _mm512_fmadd_pd(qx, qx, acc[4]);
            acc[5] = _mm512_fmadd_pd(qx, qy, acc[5]);
            acc[6] = _mm512_fmadd_pd(qx, qz, acc[6]);
            acc[7] = _mm512_fmadd_pd(qy, qy, acc[7]);
            acc[8] = _mm512_fmadd_pd(qy, qz, acc[8]);
            acc[9] = _mm512_fmadd_pd(qz, qz, acc[9]);
        }
        let t = acc.map(|v| lane_sum8(v));
        RefitSums { count: t[0], sum: [t[1], t[2], t[3]], products: [t[4], t[5], t[6], t[7], t[8], t[9]] }
    }

    /// `support` of a multiple of eight points.
    ///
    /// # Safety
    /// The CPU has AVX-512 F and VL.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(super) unsafe fn support(points: &[[f32; 3]], n: [f64; 3], offset: f64, dist: f64) -> (usize, f64) {
        let [nx, ny, nz, offset, dist] = [n[0], n[1], n[2], offset, dist].map(|v| _mm512_set1_pd(v));
        let (mut count, mut squares) = (0u32, _mm512_setzero_pd());
        for eight in points.chunks_exact(8) {
            // SAFETY: a chunk of 8 points is 24 floats.
            let [x, y, z] = unsafe { eight_points(eight.as_ptr().cast()) }.map(|v| _mm512_cvtps_pd(v));
            let r = _mm512_add_pd(
                _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(nx, x), _mm512_mul_pd(ny, y)), _mm512_mul_pd(nz, z)),
                offset,
            );
            let e = _mm512_abs_pd(r);
            let inlier = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(e, dist);
            count += inlier.count_ones();
            squares = _mm512_mask_add_pd(squares, inlier, squares, _mm512_mul_pd(e, e));
        }
        (count as usize, lane_sum8(squares))
    }
}

/// Refit's passes on four points at a time in NEON, as `avx2` does them: one structured
/// load splits four x y z triples into each coordinate's four values; the f32 distances
/// are the scalar loops' operations in the same order (no fused multiply-add), and the f64
/// sums are kept two lanes wide, each lane summing its own points.
#[cfg(target_arch = "aarch64")]
mod neon {
    use std::arch::aarch64::*;

    use super::RefitSums;

    /// The two f64 lanes of `v` added up.
    #[inline]
    #[target_feature(enable = "neon")]
    fn lane_sum(v: float64x2_t) -> f64 {
        vgetq_lane_f64::<0>(v) + vgetq_lane_f64::<1>(v)
    }

    /// The four f32 values of `v` as two pairs of f64.
    #[inline]
    #[target_feature(enable = "neon")]
    fn widen(v: float32x4_t) -> [float64x2_t; 2] {
        [vcvt_f64_f32(vget_low_f32(v)), vcvt_high_f64_f32(v)]
    }

    /// `inlier_moments` of a multiple of four points.
    ///
    /// # Safety
    /// The CPU has NEON (every aarch64 CPU does).
    #[target_feature(enable = "neon")]
    pub(super) unsafe fn inlier_moments(points: &[[f32; 3]], n: [f32; 3], d: f32, dist: f32, o: [f64; 3]) -> RefitSums {
        let [nx, ny, nz, d, dist, one] = [n[0], n[1], n[2], d, dist, 1.0].map(|v| vdupq_n_f32(v));
        let [ox, oy, oz] = o.map(|v| vdupq_n_f64(v));
        let mut acc = [vdupq_n_f64(0.0); 10];
        for quad in points.chunks_exact(4) {
            // SAFETY: a chunk of 4 points is 12 floats.
            let xyz = unsafe { vld3q_f32(quad.as_ptr().cast()) };
            let (x, y, z) = (xyz.0, xyz.1, xyz.2);
            let e = vabsq_f32(vaddq_f32(vaddq_f32(vaddq_f32(vmulq_f32(nx, x), vmulq_f32(ny, y)), vmulq_f32(nz, z)), d));
            // 1 for an inlier, 0 for an outlier: an outlier adds zeros.
            let w = vreinterpretq_f32_u32(vandq_u32(vcltq_f32(e, dist), vreinterpretq_u32_f32(one)));
            let (w, x, y, z) = (widen(w), widen(x), widen(y), widen(z));
            for h in 0..2 {
                let qx = vmulq_f64(vsubq_f64(x[h], ox), w[h]);
                let qy = vmulq_f64(vsubq_f64(y[h], oy), w[h]);
                let qz = vmulq_f64(vsubq_f64(z[h], oz), w[h]);
                acc[0] = vaddq_f64(acc[0], w[h]);
                acc[1] = vaddq_f64(acc[1], qx);
                acc[2] = vaddq_f64(acc[2], qy);
                acc[3] = vaddq_f64(acc[3], qz);
                acc[4] = vfmaq_f64(acc[4], qx, qx);
                acc[5] = vfmaq_f64(acc[5], qx, qy);
                acc[6] = vfmaq_f64(acc[6], qx, qz);
                acc[7] = vfmaq_f64(acc[7], qy, qy);
                acc[8] = vfmaq_f64(acc[8], qy, qz);
                acc[9] = vfmaq_f64(acc[9], qz, qz);
            }
        }
        let t = acc.map(|v| lane_sum(v));
        RefitSums { count: t[0], sum: [t[1], t[2], t[3]], products: [t[4], t[5], t[6], t[7], t[8], t[9]] }
    }

    /// `support` of a multiple of four points.
    ///
    /// # Safety
    /// The CPU has NEON (every aarch64 CPU does).
    #[target_feature(enable = "neon")]
    pub(super) unsafe fn support(points: &[[f32; 3]], n: [f64; 3], offset: f64, dist: f64) -> (usize, f64) {
        let [nx, ny, nz, offset, dist] = [n[0], n[1], n[2], offset, dist].map(|v| vdupq_n_f64(v));
        let (mut count, mut squares) = (vdupq_n_s64(0), vdupq_n_f64(0.0));
        for quad in points.chunks_exact(4) {
            // SAFETY: a chunk of 4 points is 12 floats.
            let xyz = unsafe { vld3q_f32(quad.as_ptr().cast()) };
            let (x, y, z) = (widen(xyz.0), widen(xyz.1), widen(xyz.2));
            for h in 0..2 {
                let r = vaddq_f64(
                    vaddq_f64(vaddq_f64(vmulq_f64(nx, x[h]), vmulq_f64(ny, y[h])), vmulq_f64(nz, z[h])),
                    offset,
                );
                let e = vabsq_f64(r);
                let inlier = vcltq_f64(e, dist);
                // An inlier's mask is -1 as an integer: subtracting it counts one.
                count = vsubq_s64(count, vreinterpretq_s64_u64(inlier));
                let square = vreinterpretq_u64_f64(vmulq_f64(e, e));
                squares = vaddq_f64(squares, vreinterpretq_f64_u64(vandq_u64(square, inlier)));
            }
        }
        ((vgetq_lane_s64::<0>(count) + vgetq_lane_s64::<1>(count)) as usize, lane_sum(squares))
    }
}

/// RANSAC then refit for every region: the whole CPU stage.
pub fn fit_planes(batch: &PointBatch, hypotheses: u32, inlier_distance: f32) -> Vec<Option<PlaneFit>> {
    let scores = score_hypotheses(batch, hypotheses, inlier_distance);
    fits_from_scores(batch, &scores, hypotheses, inlier_distance)
}

/// Each region's best hypothesis, refitted on its inliers (from either twin's scores).
pub fn fits_from_scores(
    batch: &PointBatch,
    scores: &[u32],
    hypotheses: u32,
    inlier_distance: f32,
) -> Vec<Option<PlaneFit>> {
    (0..batch.ranges.len())
        .into_par_iter()
        .map(|r| {
            let (n, d) = best_hypothesis(batch, scores, r, hypotheses)?;
            refit(&batch.points[batch.ranges[r].clone()], n, d, inlier_distance)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearly_collinear_samples_give_no_plane() {
        let (a, b) = ([0.1f32, 0.2, 1.5], [0.6f32, -0.3, 1.5]);
        // Off the line a-b by 1e-5 of its length: a cross product far above any absolute
        // floor, but mostly rounding, so no plane.
        let c = [1.1f32, -0.8, 1.5 + 0.7e-5];
        assert_eq!(plane_through(a, b, c), None);
        // Off it by 1e-2: a plane, and all three points lie on it.
        let c = [1.1f32, -0.8, 1.5 + 0.7e-2];
        let (n, d) = plane_through(a, b, c).expect("a plane");
        for p in [a, b, c] {
            assert!((n[0] * p[0] + n[1] * p[1] + n[2] * p[2] + d).abs() < 1e-6);
        }
        assert_eq!(plane_through(a, a, c), None, "two equal points");
    }

    /// `count` points of the plane n . p + d = 0, uniform within `half` of its foot along
    /// two axes in it, point i moved off it along n by `off(i)`.
    fn points_on_plane<R: rand::Rng>(
        n: Vector3<f64>,
        d: f64,
        count: usize,
        half: f64,
        rng: &mut R,
        off: impl Fn(usize, &mut R) -> f64,
    ) -> Vec<[f32; 3]> {
        use rand::RngExt;
        let (e1, e2) = (n.cross(&Vector3::x()).normalize(), n.cross(&n.cross(&Vector3::x()).normalize()));
        (0..count)
            .map(|i| {
                let off = off(i, rng);
                let p = -n * d + e1 * rng.random_range(-half..half) + e2 * rng.random_range(-half..half) + n * off;
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect()
    }

    #[test]
    fn refit_is_the_least_squares_plane_of_the_inliers_and_counts_their_support() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // A plane 2 m away with 1 mm noise, a tenth of its points 5 cm off, and sizes that
        // leave every remainder of the lanes; the first points are outliers.
        let (n, d) = (Vector3::new(0.1, -0.8, -0.6).normalize(), 2.0);
        for size in [3usize, 4, 5, 7, 1001, 20_003] {
            let points = points_on_plane(n, d, size, 0.5, &mut rng, |i, rng| {
                if i < 2 || i % 10 == 3 { 0.05 } else { rng.random_range(-0.001..0.001) }
            });
            let (nf, df) = ([n.x as f32, n.y as f32, n.z as f32], d as f32);
            let fit = refit(&points, nf, df, 0.01);
            // The plain definition: the inliers' centroid and smallest scatter direction.
            let v = |p: &[f32; 3]| Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let inliers: Vec<Vector3<f64>> =
                points.iter().filter(|p| (v(p).cast::<f32>().dot(&n.cast::<f32>()) + df).abs() < 0.01).map(v).collect();
            if inliers.len() < 3 {
                assert!(fit.is_none(), "size {size}");
                continue;
            }
            let fit = fit.expect("enough inliers");
            let c = inliers.iter().sum::<Vector3<f64>>() / inliers.len() as f64;
            let scatter = inliers.iter().map(|p| (p - c) * (p - c).transpose()).sum::<Matrix3<f64>>();
            let eig = SymmetricEigen::new(scatter);
            let mut want: Vector3<f64> = eig.eigenvectors.column(eig.eigenvalues.imin()).into();
            if want.dot(&c) > 0.0 {
                want = -want;
            }
            assert!((fit.normal - want).norm() < 1e-9, "size {size}: {} vs {want}", fit.normal);
            assert!((fit.offset + want.dot(&c)).abs() < 1e-9, "size {size}");
            let distances: Vec<f64> = points.iter().map(|p| (fit.normal.dot(&v(p)) + fit.offset).abs()).collect();
            let support: Vec<f64> = distances.iter().copied().filter(|&e| e < 0.01).collect();
            assert_eq!(fit.inliers, support.len(), "size {size}");
            assert_eq!(fit.points, size);
            let rms = (support.iter().map(|e| e * e).sum::<f64>() / support.len() as f64).sqrt();
            assert!((fit.rms - rms).abs() < 1e-12, "size {size}: rms {} vs {rms}", fit.rms);
        }
        assert!(refit(&[[0.0, 0.0, 5.0]; 10], [0.0, 0.0, -1.0], 1.0, 0.01).is_none(), "no inliers, no plane");
    }

    #[test]
    fn a_refit_in_parts_is_the_refit_of_all_the_points_on_any_number_of_threads() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        // 50 000 points of a plane 1.7 m away, 2 mm of noise, every seventh 4 cm off it,
        // and the first 3 000 all off it: the first inlier lies in the second part.
        let (n, d) = (Vector3::new(-0.2, -0.7, -0.5).normalize(), 1.7);
        let points = points_on_plane(n, d, 50_000, 0.8, &mut rng, |i, rng| {
            if i < 3000 || i % 7 == 3 { 0.04 } else { rng.random_range(-0.002..0.002) }
        });
        let (nf, df) = ([n.x as f32, n.y as f32, n.z as f32], d as f32);
        let whole = refit(&points, nf, df, 0.01).expect("a plane");
        // Parts of uneven sizes, one of them empty.
        let cuts = [0, 2000, 2000, 9001, 30_000, 50_000];
        let parts: Vec<&[[f32; 3]]> = cuts.windows(2).map(|c| &points[c[0]..c[1]]).collect();
        let fits: Vec<PlaneFit> = [1, 2, 5]
            .into_iter()
            .map(|threads| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                pool.install(|| refit_parts(&parts, nf, df, 0.01)).expect("a plane")
            })
            .collect();
        // The same sums added in another order: the same plane to rounding, the same support.
        let fit = fits[0];
        assert!((fit.normal - whole.normal).norm() < 1e-12, "{} vs {}", fit.normal, whole.normal);
        assert!((fit.offset - whole.offset).abs() < 1e-12);
        assert!((fit.rms - whole.rms).abs() < 1e-12);
        assert_eq!((fit.inliers, fit.points), (whole.inliers, whole.points));
        assert!(fit.inliers > 40_000 && fit.inliers < 43_000, "{}", fit.inliers);
        // And in the same order whatever the threads: the same bits.
        assert!(fits.iter().all(|f| *f == fit), "{fits:?}");
        assert_eq!(refit_parts(&[&points[..]], nf, df, 0.01), Some(whole), "one part is `refit`");
    }

    #[test]
    fn fast_refit_passes_are_the_scalar_ones() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        // A noisy tilted plane 1-3 m away, every fifth point off it; some points within an
        // ulp of the inlier distance, where a fused multiply-add would tip them over.
        let (n, d, dist) = ([0.2f32, -0.7, -0.685], 1.6f32, 0.01f32);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let (n, d) = (n.map(|c| c / len), d / len);
        // Every remainder of the lanes (4 or 8), and long runs.
        for size in (0usize..=17).chain([4096, 30_001]) {
            let points: Vec<[f32; 3]> = (0..size)
                .map(|i| {
                    let (x, y) = (rng.random_range(-1.0f32..1.0), rng.random_range(-0.5f32..0.8));
                    let off = match i % 5 {
                        0 => 0.05,
                        1 => dist * if i % 2 == 0 { 1.0 } else { -1.0 },
                        _ => rng.random_range(-0.003..0.003),
                    };
                    // On the plane: n . p + d = off, solved for z.
                    [x, y, (off - d - n[0] * x - n[1] * y) / n[2]]
                })
                .collect();
            let o = points.first().map_or([0.0; 3], |p| p.map(f64::from));
            let (fast, slow) = (inlier_moments(&points, n, d, dist, o), inlier_moments_scalar(&points, n, d, dist, o));
            assert_eq!(fast.count, slow.count, "size {size}: the same inliers");
            for (a, b) in fast.sum.iter().chain(&fast.products).zip(slow.sum.iter().chain(&slow.products)) {
                assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "size {size}: {a} vs {b}");
            }
            // A refitted normal has all of f64's digits (products of f32 coordinates by it round).
            let nd = n.map(|c| c as f64 + 1e-9);
            let nd = nd.map(|c| c / (nd[0] * nd[0] + nd[1] * nd[1] + nd[2] * nd[2]).sqrt());
            let ((count, squares), (want, want_squares)) =
                (support(&points, nd, d as f64, dist as f64), support_scalar(&points, nd, d as f64, dist as f64));
            assert_eq!(count, want, "size {size}: the same support");
            assert!((squares - want_squares).abs() <= 1e-12 * want_squares, "size {size}: {squares} vs {want_squares}");
            // Planes that put one point right on the support's edge, in f64 too.
            for p in points.iter().take(64) {
                let offset = dist as f64 - (nd[0] * p[0] as f64 + nd[1] * p[1] as f64 + nd[2] * p[2] as f64);
                let (count, want) =
                    (support(&points, nd, offset, dist as f64).0, support_scalar(&points, nd, offset, dist as f64).0);
                assert_eq!(count, want, "size {size}: a point on the edge of the support");
                // And the points a fit's `distance` puts within it (joins count them so).
                let fit = PlaneFit { normal: Vector3::from(nd), offset, inliers: 0, points: size, rms: 0.0 };
                let within = points.iter().filter(|p| fit.distance(p) < dist as f64).count();
                assert_eq!(count, within, "size {size}: support is PlaneFit::distance's");
            }
            if size > 100 {
                assert!(
                    slow.count > 0.5 * size as f64 && (count as f64) < 0.9 * size as f64,
                    "size {size}: outliers left out"
                );
            }
        }
    }

    #[test]
    fn fast_scores_are_the_oracle() {
        // Regions of 2, 3, 500 and 5000 points (strided above MAX_SCORE_POINTS): a noisy
        // plane with a tenth of its points off it, and (nearly) collinear points in one.
        let mut batch = PointBatch::default();
        for (r, n) in [2usize, 3, 500, 5000, 40].into_iter().enumerate() {
            let start = batch.points.len();
            for i in 0..n {
                let (a, b) = ((i % 71) as f32 * 0.01, (i / 71) as f32 * 0.01);
                let noise = ((hash(i as u32 ^ (r as u32) << 20) % 1000) as f32 / 1000.0 - 0.5) * 0.004;
                let off = if i % 10 == 0 { 0.05 } else { 0.0 };
                let p = if r == 4 { [a, a, 1.0 + a] } else { [a, b, 1.0 + 0.3 * a + noise + off] };
                batch.points.push(p);
            }
            batch.ranges.push(start..batch.points.len());
        }
        let hypotheses = 20;
        let fast = score_hypotheses(&batch, hypotheses, 0.01);
        for r in 0..batch.ranges.len() {
            for h in 0..hypotheses {
                assert_eq!(
                    fast[r * hypotheses as usize + h as usize],
                    score_at(&batch, r, h, 0.01),
                    "region {r}, hypothesis {h}"
                );
            }
        }
        let best = |r: usize| *fast[r * 20..(r + 1) * 20].iter().max().unwrap();
        assert_eq!(best(0), 0, "too few points");
        // 5000 points, every third scored: 1667, nine in ten of them on the plane.
        assert!(best(3) > 1400 && best(3) <= 1667, "a strided region scores its subset: {}", best(3));
    }
}
