//! Which vector instructions the CPU twin's loops use: the widest the CPU has, or
//! narrower where the environment variable POLYMAP_SIMD (`baseline`, `avx2`, `avx512` on
//! x86-64; `baseline`, `neon` on aarch64) caps it, to time or test the narrower paths on
//! a wide CPU. Every level computes the per-pixel stages to the same bits; the refits' and
//! covariances' f64 sums differ in their order, so in their last digits.

use std::sync::OnceLock;

/// A set of vector instructions, narrowest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// What the target was compiled for (SSE2 on x86-64, NEON on aarch64), with the
    /// hand-written vector passes off: their scalar oracles run instead.
    Baseline,
    /// Advanced SIMD (NEON), on every aarch64 CPU (a Jetson Orin's Cortex-A78AE among
    /// them): the hand-written passes four f32 or two f64 lanes wide.
    Neon,
    /// AVX2 with FMA: x86-64 since Haswell and Zen.
    Avx2,
    /// AVX-512 F, BW, VL and DQ: Skylake-X, Ice Lake, Zen 4 and later.
    Avx512,
}

impl Level {
    /// The levels this target has, narrowest first.
    #[cfg(target_arch = "x86_64")]
    pub const ALL: &[Level] = &[Level::Baseline, Level::Avx2, Level::Avx512];
    #[cfg(target_arch = "aarch64")]
    pub const ALL: &[Level] = &[Level::Baseline, Level::Neon];
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    pub const ALL: &[Level] = &[Level::Baseline];

    pub fn name(self) -> &'static str {
        match self {
            Level::Baseline => "baseline",
            Level::Neon => "neon",
            Level::Avx2 => "avx2",
            Level::Avx512 => "avx512",
        }
    }

    /// The widest level this CPU has.
    pub fn detected() -> Level {
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            if has!("avx512f") && has!("avx512bw") && has!("avx512vl") && has!("avx512dq") {
                Level::Avx512
            } else if has!("avx2") && has!("fma") {
                Level::Avx2
            } else {
                Level::Baseline
            }
        }
        // NEON is part of the aarch64 target, as SSE2 is of x86-64's.
        #[cfg(target_arch = "aarch64")]
        {
            Level::Neon
        }
        #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
        {
            Level::Baseline
        }
    }

    /// The level named by POLYMAP_SIMD's value, capped at what the CPU has.
    fn capped(value: &str, detected: Level) -> Result<Level, String> {
        let wanted = Level::ALL.iter().copied().find(|l| l.name() == value.trim()).ok_or_else(|| {
            let names: Vec<&str> = Level::ALL.iter().map(|l| l.name()).collect();
            format!("POLYMAP_SIMD={value:?} is none of {}", names.join(", "))
        })?;
        Ok(wanted.min(detected))
    }
}

/// The level the loops run at: detected once, capped by POLYMAP_SIMD. A value that names
/// no level is logged and ignored (the loops cannot fail a frame over it).
pub fn level() -> Level {
    static LEVEL: OnceLock<Level> = OnceLock::new();
    *LEVEL.get_or_init(|| {
        let detected = Level::detected();
        match std::env::var("POLYMAP_SIMD") {
            Err(_) => detected,
            Ok(value) => Level::capped(&value, detected).unwrap_or_else(|e| {
                tracing::warn!("{e}: the CPU loops use {}", detected.name());
                detected
            }),
        }
    })
}

/// The four f64 lanes of an AVX vector added up, in lane order (pairs first): how the
/// AVX2 passes that keep a sum per lane (refits, plane covariances) hand back their sums.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
pub(crate) fn lane_sum(v: std::arch::x86_64::__m256d) -> f64 {
    let mut l = [0.0f64; 4];
    // SAFETY: stores 4 f64 into a local array of 4.
    unsafe { std::arch::x86_64::_mm256_storeu_pd(l.as_mut_ptr(), v) };
    (l[0] + l[1]) + (l[2] + l[3])
}

/// The eight f64 lanes of an AVX-512 vector added up: each half by `lane_sum`, then the
/// two (pairs, then quads, as `lane_sum` orders four lanes).
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx512f")]
pub(crate) fn lane_sum8(v: std::arch::x86_64::__m512d) -> f64 {
    use std::arch::x86_64::{_mm512_castpd512_pd256, _mm512_extractf64x4_pd};
    lane_sum(_mm512_castpd512_pd256(v)) + lane_sum(_mm512_extractf64x4_pd::<1>(v))
}

/// The x, y and z of the four points at `p` (12 floats of x y z triples): three loads,
/// then two blends and a permute for each coordinate.
///
/// # Safety
/// The CPU has AVX2; 12 floats from `p` are in bounds.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
pub(crate) unsafe fn four_points(p: *const f32) -> [std::arch::x86_64::__m128; 3] {
    use std::arch::x86_64::*;
    // SAFETY: in bounds, as the caller promises; the loads are unaligned ones.
    let [a, b, c] = unsafe { [_mm_loadu_ps(p), _mm_loadu_ps(p.add(4)), _mm_loadu_ps(p.add(8))] };
    // a = x0 y0 z0 x1, b = y1 z1 x2 y2, c = z2 x3 y3 z3.
    let x = _mm_blend_ps::<0b0010>(_mm_blend_ps::<0b0100>(a, b), c); // x0 x3 x2 x1
    let y = _mm_blend_ps::<0b0100>(_mm_blend_ps::<0b1001>(a, b), c); // y1 y0 y3 y2
    let z = _mm_blend_ps::<0b1001>(_mm_blend_ps::<0b0010>(a, b), c); // z2 z1 z0 z3
    [_mm_permute_ps::<0x6C>(x), _mm_permute_ps::<0xB1>(y), _mm_permute_ps::<0xC6>(z)]
}

/// The x, y and z of the eight points at `p` (24 floats of x y z triples): two loads,
/// then one permute across both registers for each coordinate.
///
/// # Safety
/// The CPU has AVX-512 F and VL; 24 floats from `p` are in bounds.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx512f,avx512vl")]
pub(crate) unsafe fn eight_points(p: *const f32) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::*;
    // SAFETY: in bounds, as the caller promises; the loads are unaligned ones. The
    // upper half of `b` is never picked.
    let (a, b) = unsafe { (_mm512_loadu_ps(p), _mm512_castps256_ps512(_mm256_loadu_ps(p.add(16)))) };
    // Index k < 16 picks a[k], 16 + k picks b[k]: coordinate c of point i is float 3i + c.
    let pick = |c: i32| {
        let index = _mm512_setr_epi32(c, c + 3, c + 6, c + 9, c + 12, c + 15, c + 18, c + 21, 0, 0, 0, 0, 0, 0, 0, 0);
        _mm512_castps512_ps256(_mm512_permutex2var_ps(a, index, b))
    };
    [pick(0), pick(1), pick(2)]
}

/// Defines `$name` to run `$portable` (an `#[inline(always)]` fn) compiled for the
/// widest level `level()` allows: AVX-512, AVX2, or the baseline target (on aarch64 that
/// has NEON, the only level there). The loops are plain Rust either way; only the width of
/// the vectors the compiler may use differs (16 floats, 8, or 4), which multiplies their
/// throughput without tying the binary to one CPU. The compiler never fuses a multiply and
/// an add on its own, so every width computes the same bits.
macro_rules! widest_simd {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? = $portable:ident) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512dq")]
                fn avx512($($arg: $ty),*) $(-> $ret)? {
                    $portable($($arg),*)
                }
                #[target_feature(enable = "avx2")]
                fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $portable($($arg),*)
                }
                match $crate::extract::cpu::simd::level() {
                    // SAFETY: `level()` is at most what the CPU has.
                    $crate::extract::cpu::simd::Level::Avx512 => return unsafe { avx512($($arg),*) },
                    // SAFETY: as above.
                    $crate::extract::cpu::simd::Level::Avx2 => return unsafe { avx2($($arg),*) },
                    $crate::extract::cpu::simd::Level::Baseline | $crate::extract::cpu::simd::Level::Neon => {}
                }
            }
            $portable($($arg),*)
        }
    };
}
pub(crate) use widest_simd;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polymap_simd_caps_the_level_and_names_a_bad_value() {
        let widest = *Level::ALL.last().expect("a level");
        for &l in Level::ALL {
            for &cpu in Level::ALL {
                // Never above what the CPU has.
                assert_eq!(Level::capped(l.name(), cpu), Ok(l.min(cpu)), "{l:?} on {cpu:?}");
            }
        }
        assert_eq!(Level::capped(" baseline\n", widest), Ok(Level::Baseline));
        let e = Level::capped("sse4", widest).unwrap_err();
        assert!(e.contains("POLYMAP_SIMD=\"sse4\"") && e.contains("baseline"), "{e}");
        // A level of another target is no level here.
        #[cfg(target_arch = "x86_64")]
        assert!(Level::capped("neon", widest).is_err());
        #[cfg(target_arch = "aarch64")]
        assert!(Level::capped("avx2", widest).is_err());
        assert!(level() <= Level::detected());
        assert!(Level::ALL.contains(&Level::detected()));
    }
}
