//! polymap: real-time polygonal terrain mapping for legged robots.
//!
//! The library holds every stage; `src/main.rs` is a thin CLI over it.
//! Data flows depth frame -> per-frame polygons -> global polygon map -> Zenoh,
//! see README.md for the picture and `../shared/DESIGN.md` for the conventions
//! (metres, radians, nanosecond stamps, `T_a_b` maps frame b into frame a).

// `!(x > 0.0)` is how this code says "not a positive number, NaN included": the NaN is the
// point, so the negated comparison stays.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Image stencils index several rows by the same column; iterators would hide that.
#![allow(clippy::needless_range_loop)]

pub mod bench;
pub mod camera;
pub mod cli;
pub mod clock;
pub mod config;
pub mod eval;
pub mod extract;
pub mod files;
pub mod fuzz;
pub mod grid;
pub mod interface;
pub mod logs;
pub mod map;
pub mod mock;
pub mod pose;
pub mod replay;
pub mod ring;
pub mod ros1;
pub mod ros2;
pub mod runtime;
pub mod sequence;
pub mod stats;
pub mod synth;
pub mod types;
pub mod viz;

pub use types::{DepthFrame, Intrinsics, Pose};

/// Tells glibc's malloc to keep freed memory mapped. By default it gives blocks over
/// 128 KiB back to the kernel on free, and every frame's images are such blocks: the
/// next frame then page-faults them in again, thousands of faults a frame. Call once at
/// start-up.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; it is safe to call at any time.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 512 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}

/// Gives the memory freed since the last call back to the system (glibc's malloc keeps it,
/// [`keep_freed_memory`]): after a burst of large messages from peers, say.
pub fn give_back_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free pages to the kernel; it is safe to call at any time.
    unsafe {
        libc::malloc_trim(0);
    }
}
