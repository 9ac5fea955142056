//! `FitFrame::inlier_sums` and `split_halves` on several points at a time: AVX2 and
//! AVX-512 on x86-64, NEON on aarch64. Each is held to its scalar loop in `super` (the
//! oracle) by the tests there.

/// `FitFrame::inlier_sums` on four points at a time, each lane summing its own points.
/// The inlier test is the scalar loop's operations in the same order (no fused
/// multiply-add), so a point is an inlier on both or on neither, and the weight is its f32
/// operations, so the same weight; only the order of the f64 sums differs.
#[cfg(target_arch = "x86_64")]
pub(super) mod avx2 {
    use std::arch::x86_64::*;

    use crate::extract::cpu::simd::{four_points, lane_sum};
    use crate::extract::uncertainty::{FitFrame, InlierSums};

    /// The sums over a multiple of four points.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(in crate::extract::uncertainty) unsafe fn inlier_sums(f: &FitFrame, points: &[[f32; 3]]) -> InlierSums {
        let splat = |v: [f64; 3]| v.map(|c| _mm256_set1_pd(c));
        let ([nx, ny, nz], [fx, fy, fz], [ax, ay, az], [bx, by, bz]) =
            (splat(f.n), splat(f.foot), splat(f.axes[0]), splat(f.axes[1]));
        let (offset, dist, one) = (_mm256_set1_pd(f.offset), _mm256_set1_pd(f.dist), _mm256_set1_pd(1.0));
        let abs = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
        let abs32 = _mm_castsi128_ps(_mm_set1_epi32(i32::MAX));
        let (half, floor, one32) = (_mm_set1_ps(0.5), _mm_set1_ps(0.05), _mm_set1_ps(1.0));
        let dot = |x, y, z, a, b, c| {
            _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(x, a), _mm256_mul_pd(y, b)), _mm256_mul_pd(z, c))
        };
        let zero = _mm256_setzero_pd();
        let (mut count, mut scale, mut sum, mut plain, mut weighted) = (zero, zero, [zero; 3], [zero; 6], [zero; 6]);
        for quad in points.chunks_exact(4) {
            // SAFETY: a chunk of 4 points is 12 floats.
            let p = unsafe { four_points(quad.as_ptr().cast()) };
            let [x, y, z] = p.map(|c| _mm256_cvtps_pd(c));
            let np = dot(x, y, z, nx, ny, nz);
            let r = _mm256_add_pd(np, offset);
            // All ones for an inlier: everything it adds is masked with it.
            let inlier = _mm256_cmp_pd::<_CMP_LT_OQ>(_mm256_and_pd(r, abs), dist);
            let (dx, dy, dz) = (_mm256_sub_pd(x, fx), _mm256_sub_pd(y, fy), _mm256_sub_pd(z, fz));
            let (u, v) = (dot(dx, dy, dz, ax, ay, az), dot(dx, dy, dz, bx, by, bz));
            // relative_variance, in f32.
            let squares =
                _mm_add_ps(_mm_add_ps(_mm_mul_ps(p[0], p[0]), _mm_mul_ps(p[1], p[1])), _mm_mul_ps(p[2], p[2]));
            let range = _mm_sqrt_ps(squares);
            let cos = _mm_max_ps(_mm_div_ps(_mm_and_ps(_mm256_cvtpd_ps(np), abs32), range), floor);
            let spread = _mm_add_ps(half, _mm_mul_ps(half, range));
            let g2 = _mm_mul_ps(_mm_mul_ps(spread, spread), cos);
            let (inverse, g2) = (_mm256_cvtps_pd(_mm_div_ps(one32, g2)), _mm256_cvtps_pd(g2));
            let keep = |v| _mm256_and_pd(v, inlier);
            count = _mm256_add_pd(count, keep(one));
            scale = _mm256_add_pd(scale, keep(_mm256_mul_pd(_mm256_mul_pd(r, r), inverse)));
            for (s, c) in sum.iter_mut().zip([x, y, z]) {
                *s = _mm256_add_pd(*s, keep(c));
            }
            let terms = [_mm256_mul_pd(u, u), _mm256_mul_pd(u, v), _mm256_mul_pd(v, v), u, v, one].map(keep);
            for t in 0..6 {
                plain[t] = _mm256_add_pd(plain[t], terms[t]);
                weighted[t] = _mm256_fmadd_pd(terms[t], g2, weighted[t]);
            }
        }
        let total = |v| lane_sum(v);
        InlierSums {
            count: total(count),
            sum: sum.map(total),
            scale: total(scale),
            plain: plain.map(total),
            weighted: weighted.map(total),
        }
    }
}

/// `avx2`'s pass in NEON, four points at a time: one structured load splits four x y z
/// triples into each coordinate's four values; the f64 work two lanes wide (each lane
/// summing its own points), the weight's in four f32 lanes, the same operations in the same
/// order as the scalar loop's.
#[cfg(target_arch = "aarch64")]
pub(super) mod neon {
    use std::arch::aarch64::*;

    use crate::extract::uncertainty::{FitFrame, InlierSums};

    /// The sums over a multiple of four points.
    ///
    /// # Safety
    /// The CPU has NEON (every aarch64 CPU does).
    #[target_feature(enable = "neon")]
    pub(in crate::extract::uncertainty) unsafe fn inlier_sums(f: &FitFrame, points: &[[f32; 3]]) -> InlierSums {
        let splat = |v: [f64; 3]| v.map(|c| vdupq_n_f64(c));
        let ([nx, ny, nz], [fx, fy, fz], [ax, ay, az], [bx, by, bz]) =
            (splat(f.n), splat(f.foot), splat(f.axes[0]), splat(f.axes[1]));
        let (offset, dist, one) = (vdupq_n_f64(f.offset), vdupq_n_f64(f.dist), vdupq_n_f64(1.0));
        let (half, floor, one32) = (vdupq_n_f32(0.5), vdupq_n_f32(0.05), vdupq_n_f32(1.0));
        let dot = |x, y, z, a, b, c| vaddq_f64(vaddq_f64(vmulq_f64(x, a), vmulq_f64(y, b)), vmulq_f64(z, c));
        let widen = |v: float32x4_t| [vcvt_f64_f32(vget_low_f32(v)), vcvt_high_f64_f32(v)];
        let zero = vdupq_n_f64(0.0);
        let (mut count, mut scale, mut sum, mut plain, mut weighted) = (zero, zero, [zero; 3], [zero; 6], [zero; 6]);
        for quad in points.chunks_exact(4) {
            // SAFETY: a chunk of 4 points is 12 floats.
            let p = unsafe { vld3q_f32(quad.as_ptr().cast()) };
            let (x, y, z) = (widen(p.0), widen(p.1), widen(p.2));
            let np = [0, 1].map(|h| dot(x[h], y[h], z[h], nx, ny, nz));
            // relative_variance, in f32.
            let squares = vaddq_f32(vaddq_f32(vmulq_f32(p.0, p.0), vmulq_f32(p.1, p.1)), vmulq_f32(p.2, p.2));
            let range = vsqrtq_f32(squares);
            let np32 = vcvt_high_f32_f64(vcvt_f32_f64(np[0]), np[1]);
            let cos = vmaxnmq_f32(vdivq_f32(vabsq_f32(np32), range), floor);
            let spread = vaddq_f32(half, vmulq_f32(half, range));
            let g2 = vmulq_f32(vmulq_f32(spread, spread), cos);
            let (inverse, g2) = (widen(vdivq_f32(one32, g2)), widen(g2));
            for h in 0..2 {
                let r = vaddq_f64(np[h], offset);
                // All ones for an inlier: everything it adds is masked with it.
                let inlier = vcltq_f64(vabsq_f64(r), dist);
                let keep = |v: float64x2_t| vreinterpretq_f64_u64(vandq_u64(vreinterpretq_u64_f64(v), inlier));
                let (dx, dy, dz) = (vsubq_f64(x[h], fx), vsubq_f64(y[h], fy), vsubq_f64(z[h], fz));
                let (u, v) = (dot(dx, dy, dz, ax, ay, az), dot(dx, dy, dz, bx, by, bz));
                count = vaddq_f64(count, keep(one));
                scale = vaddq_f64(scale, keep(vmulq_f64(vmulq_f64(r, r), inverse[h])));
                for (s, c) in sum.iter_mut().zip([x[h], y[h], z[h]]) {
                    *s = vaddq_f64(*s, keep(c));
                }
                let terms = [vmulq_f64(u, u), vmulq_f64(u, v), vmulq_f64(v, v), u, v, one].map(keep);
                for t in 0..6 {
                    plain[t] = vaddq_f64(plain[t], terms[t]);
                    weighted[t] = vfmaq_f64(weighted[t], terms[t], g2[h]);
                }
            }
        }
        let total = |v: float64x2_t| vgetq_lane_f64::<0>(v) + vgetq_lane_f64::<1>(v);
        InlierSums {
            count: total(count),
            sum: sum.map(total),
            scale: total(scale),
            plain: plain.map(total),
            weighted: weighted.map(total),
        }
    }
}

/// `avx2`'s pass on eight points at a time: the same operations, eight lanes wide, the
/// inliers a mask register.
#[cfg(target_arch = "x86_64")]
pub(super) mod avx512 {
    use std::arch::x86_64::*;

    use crate::extract::cpu::simd::{eight_points, lane_sum8};
    use crate::extract::uncertainty::{FitFrame, HalvesCut, InlierSums, PlaneFit};

    /// The sums over a multiple of eight points.
    ///
    /// # Safety
    /// The CPU has AVX-512 F and VL.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(in crate::extract::uncertainty) unsafe fn inlier_sums(f: &FitFrame, points: &[[f32; 3]]) -> InlierSums {
        let splat = |v: [f64; 3]| v.map(|c| _mm512_set1_pd(c));
        let ([nx, ny, nz], [fx, fy, fz], [ax, ay, az], [bx, by, bz]) =
            (splat(f.n), splat(f.foot), splat(f.axes[0]), splat(f.axes[1]));
        let (offset, dist, one) = (_mm512_set1_pd(f.offset), _mm512_set1_pd(f.dist), _mm512_set1_pd(1.0));
        let abs32 = _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX));
        let (half, floor, one32) = (_mm256_set1_ps(0.5), _mm256_set1_ps(0.05), _mm256_set1_ps(1.0));
        let dot = |x, y, z, a, b, c| {
            _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(x, a), _mm512_mul_pd(y, b)), _mm512_mul_pd(z, c))
        };
        let zero = _mm512_setzero_pd();
        let (mut count, mut scale, mut sum, mut plain, mut weighted) = (zero, zero, [zero; 3], [zero; 6], [zero; 6]);
        for eight in points.chunks_exact(8) {
            // SAFETY: a chunk of 8 points is 24 floats.
            let p = unsafe { eight_points(eight.as_ptr().cast()) };
            let [x, y, z] = p.map(|c| _mm512_cvtps_pd(c));
            let np = dot(x, y, z, nx, ny, nz);
            let r = _mm512_add_pd(np, offset);
            let inlier = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_abs_pd(r), dist);
            let (dx, dy, dz) = (_mm512_sub_pd(x, fx), _mm512_sub_pd(y, fy), _mm512_sub_pd(z, fz));
            let (u, v) = (dot(dx, dy, dz, ax, ay, az), dot(dx, dy, dz, bx, by, bz));
            // relative_variance, in f32.
            let squares = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(p[0], p[0]), _mm256_mul_ps(p[1], p[1])),
                _mm256_mul_ps(p[2], p[2]),
            );
            let range = _mm256_sqrt_ps(squares);
            let cos = _mm256_max_ps(_mm256_div_ps(_mm256_and_ps(_mm512_cvtpd_ps(np), abs32), range), floor);
            let spread = _mm256_add_ps(half, _mm256_mul_ps(half, range));
            let g2 = _mm256_mul_ps(_mm256_mul_ps(spread, spread), cos);
            let (inverse, g2) = (_mm512_cvtps_pd(_mm256_div_ps(one32, g2)), _mm512_cvtps_pd(g2));
            let add = |s, v| _mm512_mask_add_pd(s, inlier, s, v);
            count = add(count, one);
            scale = add(scale, _mm512_mul_pd(_mm512_mul_pd(r, r), inverse));
            for (s, c) in sum.iter_mut().zip([x, y, z]) {
                *s = add(*s, c);
            }
            let terms = [_mm512_mul_pd(u, u), _mm512_mul_pd(u, v), _mm512_mul_pd(v, v), u, v, one];
            for t in 0..6 {
                plain[t] = add(plain[t], terms[t]);
                weighted[t] = _mm512_mask3_fmadd_pd(terms[t], g2, weighted[t], inlier);
            }
        }
        let total = |v| lane_sum8(v);
        InlierSums {
            count: total(count),
            sum: sum.map(total),
            scale: total(scale),
            plain: plain.map(total),
            weighted: weighted.map(total),
        }
    }

    /// Each point's three floats' bits in a mask of 8 points: bit 3i, 3i + 1 and 3i + 2 for
    /// point i.
    const TRIPLED: [u32; 256] = {
        let mut t = [0u32; 256];
        let mut m = 0;
        while m < 256 {
            let mut i = 0;
            while i < 8 {
                if m & (1 << i) != 0 {
                    t[m] |= 7 << (3 * i);
                }
                i += 1;
            }
            m += 1;
        }
        t
    };

    /// `split_halves` of a multiple of eight points, appended to `halves`: the inlier and
    /// side tests are `split_halves_scalar`'s operations in the same order (no fused
    /// multiply-add); each half's points are packed to the front of the 24 floats (one
    /// compress of the first 16, one of the last 8) and stored whole, so a store writes up
    /// to 16 floats past the last point kept.
    ///
    /// # Safety
    /// The CPU has AVX-512 F and VL; each half has room for 6 points more than it holds
    /// plus all of `points`.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(in crate::extract::uncertainty) unsafe fn split_halves(
        points: &[[f32; 3]],
        fit: &PlaneFit,
        dist: f64,
        cut: &HalvesCut,
        halves: &mut [Vec<[f32; 3]>; 2],
    ) {
        let splat = |v: [f64; 3]| v.map(|c| _mm512_set1_pd(c));
        let ([nx, ny, nz], [cx, cy, cz], [ax, ay, az]) =
            (splat(fit.normal.into()), splat(cut.centre.into()), splat(cut.across.into()));
        let (offset, dist, zero) = (_mm512_set1_pd(fit.offset), _mm512_set1_pd(dist), _mm512_setzero_pd());
        let dot = |x, y, z, a, b, c| {
            _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(x, a), _mm512_mul_pd(y, b)), _mm512_mul_pd(z, c))
        };
        let mut kept = [halves[0].len(), halves[1].len()];
        for eight in points.chunks_exact(8) {
            let from = eight.as_ptr().cast::<f32>();
            // SAFETY: a chunk of 8 points is 24 floats.
            let [x, y, z] = unsafe { eight_points(from) }.map(|c| _mm512_cvtps_pd(c));
            let r = _mm512_add_pd(dot(x, y, z, nx, ny, nz), offset);
            let inlier = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_abs_pd(r), dist);
            let side = dot(_mm512_sub_pd(x, cx), _mm512_sub_pd(y, cy), _mm512_sub_pd(z, cz), ax, ay, az);
            let upper = _mm512_cmp_pd_mask::<_CMP_GE_OQ>(side, zero);
            // SAFETY: as for `eight_points`.
            let (a, b) = unsafe { (_mm512_loadu_ps(from), _mm256_loadu_ps(from.add(16))) };
            for (half, mask) in [inlier & !upper, inlier & upper].into_iter().enumerate() {
                let floats = TRIPLED[mask as usize];
                let low = (floats as u16).count_ones() as usize;
                // SAFETY: the half holds kept[half] points and has room for 6 more than all
                // the points it can still take; each store writes 16 or 8 floats, from
                // within the first 3 * (kept + 8) floats of that room.
                unsafe {
                    let to = halves[half].as_mut_ptr().add(kept[half]).cast::<f32>();
                    _mm512_storeu_ps(to, _mm512_maskz_compress_ps(floats as u16, a));
                    _mm256_storeu_ps(to.add(low), _mm256_maskz_compress_ps((floats >> 16) as u8, b));
                }
                kept[half] += mask.count_ones() as usize;
            }
        }
        for (half, kept) in halves.iter_mut().zip(kept) {
            // SAFETY: the first `kept` points are written (packed, in order, above).
            unsafe { half.set_len(kept) };
        }
    }
}
