//! Which vector instructions the CPU twin's loops use: the widest the CPU has, or
//! narrower where the environment variable POLYMAP_SIMD (`baseline`, `avx2`, `avx512`)
//! caps it, to time or test the narrower paths on a wide CPU. Every level computes the
//! per-pixel stages to the same bits; the refits' and covariances' f64 sums differ in
//! their order, so in their last digits.

use std::sync::OnceLock;

/// A set of vector instructions, narrowest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// What the target was compiled for (SSE2 on x86-64).
    Baseline,
    /// AVX2 with FMA: x86-64 since Haswell and Zen.
    Avx2,
    /// AVX-512 F, BW, VL and DQ: Skylake-X, Ice Lake, Zen 4 and later.
    Avx512,
}

impl Level {
    pub const ALL: [Level; 3] = [Level::Baseline, Level::Avx2, Level::Avx512];

    pub fn name(self) -> &'static str {
        match self {
            Level::Baseline => "baseline",
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
                return Level::Avx512;
            }
            if has!("avx2") && has!("fma") {
                return Level::Avx2;
            }
        }
        Level::Baseline
    }

    /// The level named by POLYMAP_SIMD's value, capped at what the CPU has.
    fn capped(value: &str, detected: Level) -> Result<Level, String> {
        let wanted = Level::ALL
            .into_iter()
            .find(|l| l.name() == value.trim())
            .ok_or_else(|| format!("POLYMAP_SIMD={value:?} is none of baseline, avx2, avx512"))?;
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

/// Defines `$name` to run `$portable` (an `#[inline(always)]` fn) compiled for the
/// widest level `level()` allows: AVX-512, AVX2, or the baseline target. The loops are
/// plain Rust either way; only the width of the vectors the compiler may use differs
/// (16 floats, 8, or 4), which multiplies their throughput without tying the binary to
/// one CPU. The compiler never fuses a multiply and an add on its own, so every width
/// computes the same bits.
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
                    $crate::extract::cpu::simd::Level::Baseline => {}
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
        assert_eq!(Level::capped("avx2", Level::Avx512), Ok(Level::Avx2));
        assert_eq!(Level::capped(" baseline\n", Level::Avx512), Ok(Level::Baseline));
        // Never above what the CPU has.
        assert_eq!(Level::capped("avx512", Level::Avx2), Ok(Level::Avx2));
        let e = Level::capped("sse4", Level::Avx2).unwrap_err();
        assert!(e.contains("POLYMAP_SIMD=\"sse4\""), "{e}");
        assert!(level() <= Level::detected());
    }
}
