//! The CPU twin of every GPU stage, one file per shader, in plain Rust (rayon over rows).

pub mod canny;
pub mod diffusion;
pub mod normals;
pub mod ransac;
pub mod separable;

/// Rows per rayon task in the per-row loops: one row is too little work to be worth a thread hop.
pub(crate) const ROWS_PER_TASK: usize = 8;

/// Defines `$name` to run `$portable` (an `#[inline(always)]` fn) compiled for AVX2
/// when the CPU has it, else as compiled for the baseline target. The loops are plain
/// Rust either way; only the width of the vectors the compiler may use differs, which
/// doubles their throughput on x86-64 without tying the binary to one CPU.
macro_rules! widest_simd {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? = $portable:ident) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $portable($($arg),*)
                }
                if std::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2, checked just above.
                    return unsafe { avx2($($arg),*) };
                }
            }
            $portable($($arg),*)
        }
    };
}
pub(crate) use widest_simd;
