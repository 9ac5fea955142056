//! Depth units to metres: the CPU twin of shaders/metres.wgsl (0, no return, stays 0).

use crate::grid::Grid;
use crate::types::DepthFrame;

/// The frame's depth in metres; the frame is checked against its intrinsics first
/// (`extract::depth_metres`).
pub fn metres(frame: &DepthFrame) -> Grid<f32> {
    let s = frame.depth_scale as f32;
    Grid {
        width: frame.width as usize,
        height: frame.height as usize,
        data: frame.pixels.iter().map(|&d| d as f32 * s).collect(),
    }
}
