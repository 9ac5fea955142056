//! The global polygon map: each frame's polygons go to the world frame, are lowered by the
//! estimated vertical drift, and merge into the map polygons they overlap.
//!
//! A map polygon keeps its shape as a 2-D `geo` shape in a frame fixed on its plane, so a
//! merge is a true polygon union (non-convex, holes kept), simplified to a bounded vertex
//! count. Its plane is the least-squares plane of the area moments of every observation,
//! each weighted by how well its extractor knew its plane (`observation_weight`),
//! re-estimated on each merge. Clearing: a map polygon in view that the depth image
//! contradicts (the camera sees through it, or something else stands in its place) for
//! `clear_after_frames` frames in a row is removed.
//!
//! Here: the map and a frame's update, step by step. [`types`]: what planners get;
//! [`observe`]: a frame's polygons as observations, matched; [`fusion`]: entries inserted,
//! merged and published; [`clearing`]: what the depth contradicts, removed; [`snapshot`]:
//! the map as a snapshot and back ([`persist`] saves and loads them); [`validate`]: what is
//! refused, and why.

mod clearing;
pub mod convex;
pub mod drift;
pub mod elevation;
pub mod foothold;
mod fusion;
pub mod geometry;
pub mod labels;
mod observe;
pub mod persist;
mod register;
pub mod render;
mod snapshot;
mod types;
pub mod validate;

use std::collections::BTreeMap;

use geo::{Area, BooleanOps, Centroid, Contains, Coord, MinimumRotatedRect, Point, Polygon as Shape};
use nalgebra::{Isometry3, Matrix4, Point3, Vector3};
use rstar::primitives::{GeomWithData, Rectangle};
use rstar::{AABB, RTree};
use serde::{Deserialize, Serialize};

use crate::config::MapConfig;
use crate::extract::uncertainty::{Footing, PlaneUncertainty, footing, in_plane_axes};
use crate::extract::{Grid, Polygon, VertexKind};
use crate::types::{Intrinsics, Pose};
use clearing::*;
use drift::{DriftFilter, DriftNoise};
use fusion::*;
use geometry::{Moments, Plane, PlaneFrame, ViewPyramid};
pub use labels::{Label, Stair};
use observe::*;
pub use register::Registration;
use types::unknown_covariance;
pub use types::{MapCounters, MapFrame, MapPolygon, MapSnapshot, MapUpdate, Region};
pub use validate::{PolygonProblem, Rejection, SnapshotProblem, polygon_problem};

/// A map polygon's state: its shape on its plane frame and what it has seen.
#[derive(Clone, Debug)]
struct Entry {
    frame: PlaneFrame,
    shape: Shape<f64>,
    moments: Moments,
    plane: Plane,
    /// Every observation's plane covariance fused, about the first one's centre and axes.
    uncertainty: PlaneUncertainty,
    /// The most pixels one frame saw it with.
    most_pixels: u32,
    observations: u32,
    /// Frames in a row that contradicted it.
    misses: u32,
    /// World axis-aligned box of the outline, for quick rejection.
    aabb: [[f64; 3]; 2],
    area: f64,
    centroid: [f64; 3],
    /// What labelling needs of it (its label and step are in the map's label table).
    facts: labels::Facts,
    /// Points inside the shape that clearing checks against the depth image.
    samples: Vec<Coord<f64>>,
    /// The planner's view, built when asked for and dropped when the entry changes.
    published: Option<MapPolygon>,
    /// In `frame`: what frames saw (less what a later frame looked at and did not see),
    /// what two frames saw, and the latest frame's view as seen; `shape` is the union of
    /// the first and the last.
    seen: Option<Shape<f64>>,
    confirmed: Option<Shape<f64>>,
    latest: Option<Shape<f64>>,
}

/// A frame polygon in the world, ready to match.
struct Observation {
    boundary: Vec<[f64; 3]>,
    holes: Vec<Vec<[f64; 3]>>,
    plane: Plane,
    moments: Moments,
    uncertainty: PlaneUncertainty,
    /// The pixels its frame saw it with (a snapshot: the most any frame did).
    pixels: u32,
    aabb: [[f64; 3]; 2],
    /// How far each vertex of its outline (then of each hole) is pulled in before what it
    /// bounds is kept, m: its outline's uncertainty where that vertex was seen.
    erode: Vec<f64>,
    erode_holes: Vec<Vec<f64>>,
    /// Where its frame looked (None: a snapshot, which looked nowhere).
    view: Option<ViewPyramid>,
}

impl Observation {
    /// Its shape in `frame`, each vertex pulled in by its outline's uncertainty there
    /// (None if nothing is left).
    fn shape_in(&self, frame: &PlaneFrame) -> Option<Shape<f64>> {
        let s = frame.shape(&self.boundary, &self.holes);
        if self.erode.iter().chain(self.erode_holes.iter().flatten()).all(|&d| d <= 0.0) {
            return Some(s);
        }
        let outline = geometry::inset_ring(frame, &self.boundary, &self.erode, true);
        let holes = self.holes.iter().zip(&self.erode_holes).map(|(h, d)| geometry::inset_ring(frame, h, d, false));
        // Pulled in vertex by vertex, a thin part can fold over: the fold is cut away.
        geometry::intersection(&Shape::new(outline, holes.collect()), &s)
    }
}

/// A map polygon an observation overlaps: its id, the overlap area and the observation's
/// height over it (along the map polygon's normal) at the overlap's centroid.
struct Match {
    id: u64,
    area: f64,
    dz: f64,
    /// The overlap's centroid on the map polygon's plane frame, world.
    at: Vector3<f64>,
}

#[derive(Clone)]
pub struct PolygonMap {
    cfg: MapConfig,
    entries: BTreeMap<u64, Entry>,
    /// Each entry's world box, by id: matching and clearing look up what is near instead
    /// of scanning the map.
    index: RTree<Indexed>,
    /// What labelling needs of every entry, kept as they change.
    label_table: labels::Table,
    next_id: u64,
    pub drift: DriftFilter,
    /// The last frames' corrected poses: what tells a step of the odometry from motion.
    track: register::Track,
    /// One more with every frame merged: what a client applied up to.
    version: u64,
    stair: Option<Stair>,
    pub counters: MapCounters,
}

/// Fewest depth samples of a map polygon in view for clearing to judge it.
const MIN_CLEAR_SAMPLES: usize = 8;
/// Samples a polygon gets for clearing (spread on a grid over its shape).
const CLEAR_SAMPLES: f64 = 48.0;
/// The most grid points across a shape's box that clearing samples are taken from.
const MAX_SAMPLE_GRID: f64 = 64.0;
/// Samples seen at a grazing angle (ray within ~9 deg of the plane) are not judged.
const MIN_VIEW_COS: f64 = 0.15;
/// Something over a surface's footprint nearer to it than this stands in its place, m.
const OCCLUDER_M: f64 = 0.3;

impl PolygonMap {
    pub fn new(cfg: &MapConfig) -> PolygonMap {
        PolygonMap {
            cfg: cfg.clone(),
            entries: BTreeMap::new(),
            index: RTree::new(),
            label_table: labels::Table::new(cfg.horizontal_max_tilt_deg, cfg.vertical_min_tilt_deg),
            next_id: 1,
            drift: DriftFilter::new(DriftNoise::from(cfg)),
            track: register::Track::default(),
            version: 0,
            stair: None,
            counters: MapCounters::default(),
        }
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The map's version: one more with every frame merged (a frame whose pose is refused
    /// changes nothing and leaves it). Updates carry the version they apply to and the one
    /// they make, snapshots theirs, so a client can tell what it missed.
    pub fn version(&self) -> u64 {
        self.version
    }

    pub fn stair(&self) -> Option<&Stair> {
        self.stair.as_ref()
    }

    /// The pose with the drift estimate taken out: what the map's frame says the camera is.
    pub fn corrected(&self, t_world_camera: &Isometry3<f64>) -> Isometry3<f64> {
        self.drift.transform().inverse() * t_world_camera
    }

    /// Merges one frame: `polygons` in the camera frame, `pose` the odometry's (its stamp
    /// tells a step of the odometry from motion), `depth_m` the frame's depth in metres for
    /// clearing (None: nothing is cleared).
    pub fn update(
        &mut self,
        polygons: &[Polygon],
        pose: &Pose,
        intrinsics: &Intrinsics,
        depth_m: Option<&Grid<f32>>,
    ) -> MapUpdate {
        let t_world_camera = &pose.transform;
        let mut update = MapUpdate::default();
        self.counters.frames += 1;
        self.counters.polygons_in += polygons.len() as u64;
        let Some(valid) = self.admit(polygons, t_world_camera, &mut update) else { return update };
        self.version += 1;
        if self.cfg.drift_filter {
            update.odometry_step = self.take_odometry_step(&valid, pose, intrinsics);
            update.registration = self.register(&valid, t_world_camera, intrinsics);
        }
        let touched = self.merge_frame(&valid, t_world_camera, intrinsics, &mut update);
        update.placed = valid.iter().map(|p| p.id).zip(touched.iter().copied()).collect();
        if let Some(depth_m) = depth_m {
            self.clear_contradicted(&touched, t_world_camera, depth_m, intrinsics, &mut update);
        }
        self.settle(&touched, &mut update);
        self.track.push(pose.stamp_ns, self.corrected(t_world_camera));
        update
    }

    /// The polygons fit to go in, the others refused in `update` with why; None (the frame
    /// skipped) when the pose itself is unusable.
    fn admit<'p>(
        &mut self,
        polygons: &'p [Polygon],
        t_world_camera: &Isometry3<f64>,
        update: &mut MapUpdate,
    ) -> Option<Vec<&'p Polygon>> {
        let valid: Vec<&Polygon> = polygons
            .iter()
            .filter(|p| match polygon_problem(p) {
                Some(problem) => {
                    update.rejected.push(Rejection::Polygon { id: p.id as u64, problem });
                    false
                }
                None => true,
            })
            .collect();
        let t = t_world_camera.translation.vector;
        let pose_finite = t.iter().chain(t_world_camera.rotation.coords.iter()).all(|v| v.is_finite())
            && t.norm() <= crate::types::MAX_COORDINATE_M;
        if !pose_finite {
            update
                .rejected
                .push(Rejection::Pose { translation: [t.x, t.y, t.z], max_m: crate::types::MAX_COORDINATE_M });
        }
        self.counters.rejected += update.rejected.len() as u64;
        for why in &update.rejected {
            tracing::warn!("map: {why}");
        }
        pose_finite.then_some(valid)
    }

    /// Each polygon, drift taken out, merged into the map polygons it matches (bridged ones
    /// absorbed into the largest overlap) or added; against the map as it grows within the
    /// frame. Returns the ids touched.
    fn merge_frame(
        &mut self,
        valid: &[&Polygon],
        t_world_camera: &Isometry3<f64>,
        intrinsics: &Intrinsics,
        update: &mut MapUpdate,
    ) -> Vec<u64> {
        let mut touched = Vec::new();
        for o in self.observations(valid, t_world_camera, intrinsics) {
            let mut matches = self.matches(&o);
            matches.sort_by(|a, b| b.area.total_cmp(&a.area));
            let id = match matches.first() {
                None => {
                    let id = self.next_id;
                    self.next_id += 1;
                    self.insert(id, &o);
                    update.added.push(id);
                    id
                }
                Some(best) => {
                    let id = best.id;
                    for other in &matches[1..] {
                        self.absorb(id, other.id);
                        update.removed.push(other.id);
                        // An earlier polygon of this frame that went into it went into `id`.
                        touched.iter_mut().filter(|t| **t == other.id).for_each(|t| *t = id);
                    }
                    self.merge(id, &o);
                    update.changed.push(id);
                    id
                }
            };
            touched.push(id);
        }
        self.counters.added += update.added.len() as u64;
        self.counters.merged += update.changed.len() as u64;
        touched
    }

    /// One map polygon as planners see it (built on first request after a change).
    pub fn polygon(&mut self, id: u64) -> Option<MapPolygon> {
        let margin = self.cfg.foot_margin_m;
        let e = self.entries.get_mut(&id)?;
        if e.published.is_none() {
            e.published = Some(publish(id, e, self.label_table.labelled(id), margin));
        }
        e.published.clone()
    }

    pub fn ids(&self) -> Vec<u64> {
        self.entries.keys().copied().collect()
    }

    /// Map polygon `id`'s label, if the map holds it.
    pub fn label(&self, id: u64) -> Option<Label> {
        self.entries.contains_key(&id).then(|| self.label_table.labelled(id).0)
    }
}
