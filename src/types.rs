//! Plain data types shared by every stage.

use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Nanoseconds on the one clock that depth frames and poses share.
pub type StampNs = u64;

/// The world polymap maps reaches this far from its origin, m: a pose or a vertex further
/// out is not a place a robot walks, and the polygon booleans lose their footing there.
pub const MAX_COORDINATE_M: f64 = 1e6;

/// Pinhole intrinsics of a depth image, with its depth unit.
///
/// Pixel centres sit at integer coordinates (OpenCV convention): the ray of
/// pixel (u, v) passes through ((u - cx) / fx, (v - cy) / fy, 1) in the
/// camera's optical frame (x right, y down, z forward).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Metres per depth unit (L515: 0.00025, D4xx: 0.001).
    pub depth_scale: f64,
}

impl Intrinsics {
    /// The L515 at 320x240 as the reference implementation ran it.
    pub const L515_320X240: Intrinsics = Intrinsics {
        width: 320,
        height: 240,
        fx: 228.686,
        fy: 230.078,
        cx: 157.748,
        cy: 123.968,
        depth_scale: 0.00025,
    };

    /// The same optics at another resolution (same field of view).
    pub fn scaled_to(&self, width: u32, height: u32) -> Intrinsics {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        // Pixel centres at integers: scale the edges (c + 0.5), not the centres.
        Intrinsics {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
            depth_scale: self.depth_scale,
        }
    }

    /// Why these intrinsics cannot be used, naming the field; `None` if they can.
    pub fn problem(&self) -> Option<String> {
        if self.width == 0 || self.height == 0 || self.width > 8192 || self.height > 8192 {
            return Some(format!("width x height {}x{} must be within 1..=8192", self.width, self.height));
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Some(format!("{name} = {v} must be a positive focal length in pixels"));
            }
        }
        for (name, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Some(format!("{name} = {v} must be finite"));
            }
        }
        if !(self.depth_scale.is_finite() && self.depth_scale > 0.0 && self.depth_scale < 1.0) {
            return Some(format!("depth_scale = {} must be metres per depth unit, in (0, 1)", self.depth_scale));
        }
        None
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Direction of pixel (u, v)'s ray in the camera frame, with z = 1, so that
    /// `ray * depth` is the back-projected point.
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        Vector3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    pub fn back_project(&self, u: f64, v: f64, depth_m: f64) -> Point3<f64> {
        Point3::from(self.ray(u, v) * depth_m)
    }

    /// Pixel coordinates of a camera-frame point (z > 0).
    pub fn project(&self, p: &Point3<f64>) -> (f64, f64) {
        (self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }
}

/// One depth image as a sensor delivers it.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthFrame {
    pub stamp_ns: StampNs,
    pub width: u32,
    pub height: u32,
    /// Metres per unit of `pixels`.
    pub depth_scale: f64,
    /// Row-major depth units, 0 = invalid.
    pub pixels: Vec<u16>,
}

impl DepthFrame {
    pub fn depth_m(&self, u: u32, v: u32) -> Option<f64> {
        let d = self.pixels[(v * self.width + u) as usize];
        (d != 0).then_some(d as f64 * self.depth_scale)
    }
}

/// A rigid transform with its stamp: `T_world_x` maps points of frame x into world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub stamp_ns: StampNs,
    pub transform: Isometry3<f64>,
}

/// Seconds (as written in TUM files) to nanoseconds, rejecting what cannot be a stamp.
pub fn seconds_to_ns(s: f64) -> Option<StampNs> {
    (s.is_finite() && (0.0..1.8e10).contains(&s)).then(|| (s * 1e9).round() as StampNs)
}

/// Nanoseconds as decimal seconds with all nine digits, so that stamps round-trip exactly.
pub fn ns_to_seconds_string(ns: StampNs) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}
