//! polymap: real-time polygonal terrain mapping for legged robots.
//!
//! The library holds every stage; `src/main.rs` is a thin CLI over it.
//! Data flows depth frame -> per-frame polygons -> global polygon map -> Zenoh,
//! see README.md for the picture and `../shared/DESIGN.md` for the conventions
//! (metres, radians, nanosecond stamps, `T_a_b` maps frame b into frame a).

pub mod bench;
pub mod bus;
pub mod camera;
pub mod config;
pub mod eval;
pub mod extract;
pub mod live;
pub mod map;
pub mod mock_vins;
pub mod pose;
pub mod replay;
pub mod ros;
pub mod sequence;
pub mod synth;
pub mod types;
pub mod viz;

pub use types::{DepthFrame, Intrinsics, Pose};
