//! The map's public types: its polygons as planners get them, a snapshot, what a frame
//! changed, and the running totals.

use super::*;

/// One map polygon as planners get it (world frame, metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapPolygon {
    pub id: u64,
    pub label: Label,
    /// Unit normal; up for horizontal polygons.
    pub normal: [f64; 3],
    /// Plane offset: normal . p + offset = 0.
    pub offset: f64,
    /// m^2, holes excluded.
    pub area: f64,
    pub centroid: [f64; 3],
    pub boundary: Vec<[f64; 3]>,
    pub holes: Vec<Vec<[f64; 3]>>,
    /// Convex pieces whose union is the insets: where a foot fits whole.
    pub convex_pieces: Vec<Vec<[f64; 3]>>,
    /// The polygon shrunk by the foot margin: every piece that is left, each with its holes
    /// (grown by the margin); empty when nothing is left.
    #[serde(default)]
    pub insets: Vec<Region>,
    /// Frames that saw it.
    pub observations: u32,
    /// Step index for treads, landings and risers; 0 for the floor.
    pub step: Option<u32>,
    /// Covariance of the plane's coefficients (normal x, y, z, offset), row-major: the
    /// observations' plane covariances fused (extract::uncertainty). All zero when unknown
    /// (no observation said; a snapshot keeps it).
    #[serde(default = "unknown_covariance")]
    pub plane_covariance: [f64; 16],
    /// Whether a foot may trust its plane: the frame polygons' rule (extract::uncertainty::
    /// footing) on the fused covariance and the most pixels one frame saw it with, so a
    /// polygon becomes steppable as observations shrink its covariance.
    #[serde(default = "Footing::unknown")]
    pub footing: Footing,
    /// The most pixels one frame saw it with.
    #[serde(default)]
    pub pixels: u32,
}

pub(super) fn unknown_covariance() -> [f64; 16] {
    [0.0; 16]
}

impl MapPolygon {
    /// The height of its plane over (x, y), seen from above (not for vertical polygons).
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        -(self.normal[0] * x + self.normal[1] * y + self.offset) / self.normal[2]
    }
}

/// A polygon with holes on a map polygon's plane (world frame, metres): outline
/// counter-clockwise seen from above the plane, holes clockwise, no closing repeat.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Region {
    pub boundary: Vec<[f64; 3]>,
    pub holes: Vec<Vec<[f64; 3]>>,
}

/// The frame a snapshot's coordinates are in: the map's own, the odometry's world with
/// the drift taken out; written "world" (a snapshot in any other is refused as it is read).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MapFrame {
    #[default]
    World,
}

/// The whole map as saved and published.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapSnapshot {
    /// The map's version: one more with every frame merged (see [`PolygonMap::version`]).
    #[serde(default)]
    pub version: u64,
    pub frame: MapFrame,
    /// Estimated vertical drift of the odometry, m.
    pub drift_z: f64,
    /// Its variance, m^2.
    pub drift_var: f64,
    /// The horizontal drift, m, and the yaw's, rad: the odometry puts a map point p at
    /// R_z(drift_yaw) p + (drift_xy, drift_z).
    #[serde(default)]
    pub drift_xy: [f64; 2],
    #[serde(default)]
    pub drift_yaw: f64,
    /// Covariance of the map frame's error (x, y, z, yaw at 1 m), m^2 (older snapshots:
    /// none, the vertical variance alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift_covariance: Option<[[f64; 4]; 4]>,
    #[serde(default)]
    pub stair: Option<Stair>,
    pub polygons: Vec<MapPolygon>,
}

/// What one frame changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapUpdate {
    pub added: Vec<u64>,
    pub changed: Vec<u64>,
    pub removed: Vec<u64>,
    /// Where each of the frame's polygons went: (its id in the frame, the map polygon's id).
    pub placed: Vec<(u32, u64)>,
    /// What the frame's planes said of the drift (None: nothing matched, or no filter).
    pub registration: Option<super::Registration>,
    /// A step of the odometry was taken into the drift before the frame was merged.
    pub odometry_step: bool,
    /// What was refused, each with why.
    pub rejected: Vec<Rejection>,
}

/// Running totals, for status and logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MapCounters {
    pub frames: u64,
    pub polygons_in: u64,
    pub rejected: u64,
    pub merged: u64,
    pub added: u64,
    pub removed: u64,
    pub cleared: u64,
    /// Steps of the odometry taken into the drift.
    pub odometry_steps: u64,
    /// Registration rows dropped as wrong matches.
    pub registration_outliers: u64,
}
