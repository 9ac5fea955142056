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

pub mod convex;
pub mod drift;
pub mod elevation;
pub mod foothold;
pub mod geometry;
pub mod labels;
pub mod persist;
pub mod render;
pub mod validate;

use std::collections::BTreeMap;

use geo::{Area, BooleanOps, Centroid, Contains, Coord, MinimumRotatedRect, Point, Polygon as Shape};
use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use rstar::primitives::{GeomWithData, Rectangle};
use rstar::{AABB, RTree};
use serde::{Deserialize, Serialize};

use crate::config::MapConfig;
use crate::extract::uncertainty::{PlaneUncertainty, in_plane_axes};
use crate::extract::{Grid, Polygon, VertexKind};
use crate::types::Intrinsics;
use drift::DriftFilter;
use geometry::{Moments, Plane, PlaneFrame, ViewPyramid};
pub use labels::{Label, Stair};
pub use validate::{PolygonProblem, Rejection, SnapshotProblem, polygon_problem};

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
}

fn unknown_covariance() -> [f64; 16] {
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

/// The whole map as saved and published.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapSnapshot {
    /// The map's version: one more with every frame merged (see [`PolygonMap::version`]).
    #[serde(default)]
    pub version: u64,
    /// Always "world".
    pub frame: String,
    /// Estimated vertical drift of the odometry, m.
    pub drift_z: f64,
    /// Its variance, m^2.
    pub drift_var: f64,
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
    /// The drift this frame measured (before filtering), m.
    pub drift_measured: Option<f64>,
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
}

/// A map polygon's state: its shape on its plane frame and what it has seen.
#[derive(Clone, Debug)]
struct Entry {
    frame: PlaneFrame,
    shape: Shape<f64>,
    moments: Moments,
    plane: Plane,
    /// Every observation's plane covariance fused, about the first one's centre and axes.
    uncertainty: PlaneUncertainty,
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
    aabb: [[f64; 3]; 2],
    horizontal: bool,
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
            drift: DriftFilter::new(cfg.drift_sigma_p, cfg.drift_sigma_m),
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
        Translation3::new(0.0, 0.0, -self.drift.z) * t_world_camera
    }

    /// Merges one frame: `polygons` in the camera frame, `t_world_camera` the odometry's pose,
    /// `depth_m` the frame's depth in metres for clearing (None: nothing is cleared).
    pub fn update(
        &mut self,
        polygons: &[Polygon],
        t_world_camera: &Isometry3<f64>,
        intrinsics: &Intrinsics,
        depth_m: Option<&Grid<f32>>,
    ) -> MapUpdate {
        let mut update = MapUpdate::default();
        self.counters.frames += 1;
        self.counters.polygons_in += polygons.len() as u64;
        let Some(valid) = self.admit(polygons, t_world_camera, &mut update) else { return update };
        self.version += 1;
        if self.cfg.drift_filter {
            update.drift_measured = self.measure_drift(&valid, t_world_camera, intrinsics);
        }
        let touched = self.merge_frame(&valid, t_world_camera, intrinsics, &mut update);
        if let Some(depth_m) = depth_m {
            self.clear_contradicted(&touched, t_world_camera, depth_m, intrinsics, &mut update);
        }
        self.settle(&touched, &mut update);
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

    /// Drift: predicted, measured on the frame's horizontal polygons that match horizontal
    /// map polygons (area-weighted height difference), corrected. Returns the measurement.
    fn measure_drift(
        &mut self,
        valid: &[&Polygon],
        t_world_camera: &Isometry3<f64>,
        intrinsics: &Intrinsics,
    ) -> Option<f64> {
        self.drift.predict();
        let obs = self.observations(valid, t_world_camera, intrinsics);
        let (mut weight, mut sum) = (0.0, 0.0);
        for o in obs.iter().filter(|o| o.horizontal) {
            for m in self.matches(o) {
                if self.label_table.labelled(m.id).0.is_horizontal() {
                    weight += m.area;
                    sum += m.area * m.dz * self.entries[&m.id].frame.normal.z;
                }
            }
        }
        if weight <= 0.0 {
            return None;
        }
        let measured = self.drift.z + sum / weight;
        self.drift.correct(measured);
        tracing::debug!(
            "drift measured {:.1} mm over {weight:.3} m^2 -> estimate {:.1} mm",
            measured * 1e3,
            self.drift.z * 1e3
        );
        Some(measured)
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

    /// Map polygons in view that this frame did not see and whose place the depth image
    /// contradicts get a miss; `clear_after_frames` misses in a row remove them. Only map
    /// polygons the view can reach are looked at ([`ViewBox`]), so the cost follows what
    /// is in view, not the map's size.
    fn clear_contradicted(
        &mut self,
        touched: &[u64],
        t_world_camera: &Isometry3<f64>,
        depth_m: &Grid<f32>,
        intrinsics: &Intrinsics,
        update: &mut MapUpdate,
    ) {
        let camera = self.corrected(t_world_camera);
        let Some(reach) = ViewBox::new(&camera, depth_m, intrinsics, &self.cfg) else { return };
        let mut in_view: Vec<u64> = self.index.locate_in_envelope_intersecting(&reach.0).map(|g| g.data).collect();
        in_view.sort_unstable();
        let mut cleared = Vec::new();
        for id in in_view.into_iter().filter(|id| !touched.contains(id)) {
            let e = self.entries.get_mut(&id).expect("the index holds the entries");
            match contradiction(e, &camera, depth_m, intrinsics, &self.cfg) {
                Some(true) => {
                    e.misses += 1;
                    if e.misses >= self.cfg.clear_after_frames {
                        cleared.push(id);
                    }
                }
                Some(false) => e.misses = 0,
                None => {}
            }
        }
        for id in cleared {
            tracing::debug!("map polygon {id} cleared: contradicted {} frames in a row", self.cfg.clear_after_frames);
            self.remove(id);
            update.removed.push(id);
            self.counters.cleared += 1;
        }
    }

    /// The frame's bookkeeping: what it touched has no misses, the lists of `update` are
    /// sorted and hold each id once (what was added or changed and then removed is only
    /// removed), labels are redone.
    fn settle(&mut self, touched: &[u64], update: &mut MapUpdate) {
        for id in touched {
            if let Some(e) = self.entries.get_mut(id) {
                e.misses = 0;
            }
        }
        update.removed.sort_unstable();
        update.removed.dedup();
        update.added.retain(|id| self.entries.contains_key(id));
        update.changed.retain(|id| self.entries.contains_key(id) && !update.added.contains(id));
        update.changed.sort_unstable();
        update.changed.dedup();
        self.counters.removed += update.removed.len() as u64;
        for id in self.relabel() {
            if !update.added.contains(&id) && !update.changed.contains(&id) {
                update.changed.push(id);
            }
        }
    }

    /// The frame's polygons in the world, drift taken out.
    fn observations(
        &self,
        polygons: &[&Polygon],
        t_world_camera: &Isometry3<f64>,
        intrinsics: &Intrinsics,
    ) -> Vec<Observation> {
        let t = self.corrected(t_world_camera);
        let view = ViewPyramid::new(&t, intrinsics, LOOKED_MARGIN_PX);
        let cos_h = self.cfg.horizontal_max_tilt_deg.to_radians().cos();
        polygons
            .iter()
            .map(|p| {
                // How far each vertex is pulled in follows from what the extractor says it
                // lies on: a cut at a neighbour's plane is exact and stays put.
                let erode_at = |ring: &[[f64; 3]], kinds: &[VertexKind]| -> Vec<f64> {
                    ring.iter()
                        .zip(kinds)
                        .map(|(v, kind)| {
                            let px = match kind {
                                VertexKind::Cut { .. } => return 0.0,
                                VertexKind::ImageBorder => VIEW_EDGE_UNCERTAINTY_PX,
                                VertexKind::Inside => OUTLINE_UNCERTAINTY_PX,
                            };
                            (px * footprint(v, p, intrinsics)).min(MAX_ERODE_M)
                        })
                        .collect()
                };
                let erode = erode_at(&p.boundary, &p.boundary_kinds);
                let erode_holes = p.holes.iter().zip(&p.hole_kinds).map(|(h, k)| erode_at(h, k)).collect();
                let w = p.transformed(&t);
                let mut normal = Vector3::from(w.normal);
                let mut offset = w.offset;
                let horizontal = normal.z.abs() >= cos_h;
                if horizontal && normal.z < 0.0 {
                    normal = -normal;
                    offset = -offset;
                }
                let surface = Moments::of_polygon(&w.boundary, &w.holes, &normal);
                let moments = surface.scaled(observation_weight(&w.uncertainty, &surface));
                Observation {
                    aabb: aabb(&w.boundary),
                    plane: Plane { normal, offset },
                    moments,
                    uncertainty: w.uncertainty,
                    horizontal,
                    erode,
                    erode_holes,
                    view: Some(view),
                    boundary: w.boundary,
                    holes: w.holes,
                }
            })
            .collect()
    }

    /// Map polygons that `o` overlaps enough, with normals and heights that agree.
    fn matches(&self, o: &Observation) -> Vec<Match> {
        let cos_n = self.cfg.merge_normal_tolerance_deg.to_radians().cos();
        let tol = self.cfg.merge_height_tolerance_m;
        let (lo, hi) = (o.aabb[0].map(|v| v - tol), o.aabb[1].map(|v| v + tol));
        let mut near: Vec<u64> =
            self.index.locate_in_envelope_intersecting(&AABB::from_corners(lo, hi)).map(|g| g.data).collect();
        // In id order, as a scan of the map would meet them: ties of overlap keep that order.
        near.sort_unstable();
        let mut out = Vec::new();
        for id in near {
            let e = &self.entries[&id];
            if o.plane.normal.dot(&e.plane.normal).abs() < cos_n {
                continue;
            }
            let shape = e.frame.shape(&o.boundary, &o.holes);
            let (area, centre) = geometry::overlap(&shape, &e.shape);
            let Some(c) = centre else { continue };
            if area < self.cfg.merge_min_overlap * shape.unsigned_area().min(e.area) {
                continue;
            }
            let q = e.frame.origin + e.frame.e1 * c.x + e.frame.e2 * c.y;
            let (Some(t_obs), Some(t_map)) = (o.plane.along(&q, &e.frame.normal), e.plane.along(&q, &e.frame.normal))
            else {
                continue;
            };
            let dz = t_obs - t_map;
            if dz.abs() <= tol {
                out.push(Match { id, area, dz });
            }
        }
        out
    }

    /// A new entry `id` made of one observation.
    fn insert(&mut self, id: u64, o: &Observation) {
        let centre = o.moments.sum / o.moments.weight.max(1e-12);
        let frame = PlaneFrame::new(centre, o.plane.normal);
        let as_seen = frame.shape(&o.boundary, &o.holes);
        let shape = geometry::simplify_to(&as_seen, self.cfg.max_vertices);
        let mut e = Entry {
            frame,
            shape,
            moments: o.moments,
            plane: o.plane,
            uncertainty: o.uncertainty,
            observations: 1,
            misses: 0,
            aabb: o.aabb,
            area: 0.0,
            centroid: [0.0; 3],
            facts: labels::Facts::default(),
            samples: Vec::new(),
            published: None,
            seen: o.shape_in(&frame),
            confirmed: None,
            latest: Some(as_seen),
        };
        refresh(&mut e);
        self.entries.insert(id, e);
        self.file(id);
    }

    /// Unions observation `o` into entry `id` and refits its plane.
    fn merge(&mut self, id: u64, o: &Observation) {
        let max_vertices = self.cfg.max_vertices;
        self.unfile(id);
        let e = self.entries.get_mut(&id).expect("matched entries exist");
        if let Some(view) = o.shape_in(&e.frame) {
            // What two frames saw is confirmed and stays. What one frame saw stays until a
            // later frame looks there and does not see it: one frame's stray overshoot (a
            // leak, a mixed-pixel fringe) goes with the next look, while the far end of a
            // surface that only one frame reached stays.
            if let Some(twice) = e.seen.as_ref().and_then(|s| geometry::intersection(s, &view)) {
                e.confirmed = union_into(e.confirmed.take(), twice, max_vertices);
            }
            let looked = o.view.and_then(|v| v.on_plane(&e.frame));
            e.seen = looked_again(e.seen.take(), looked.as_ref(), view, e.confirmed.as_ref(), max_vertices);
            // Each place shows as the latest frame to look there saw it, not pulled in.
            let as_seen = e.frame.shape(&o.boundary, &o.holes);
            e.latest = looked_again(e.latest.take(), looked.as_ref(), as_seen, None, max_vertices);
            e.shape = shown(e.seen.as_ref(), e.latest.as_ref(), max_vertices).unwrap_or(e.shape.clone());
        }
        e.uncertainty = e.uncertainty.fused_with(&o.uncertainty);
        refit(e, &o.moments, 1);
        self.file(id);
    }

    /// Entry `other` merged into `id` (one observation bridged them), then dropped.
    fn absorb(&mut self, id: u64, other: u64) {
        let Some(o) = self.remove(other) else { return };
        let max_vertices = self.cfg.max_vertices;
        self.unfile(id);
        let e = self.entries.get_mut(&id).expect("matched entries exist");
        let boundary = o.frame.lift_ring(o.shape.exterior(), &o.plane);
        let holes: Vec<_> = o.shape.interiors().iter().map(|r| o.frame.lift_ring(r, &o.plane)).collect();
        let theirs = e.frame.shape(&boundary, &holes);
        e.seen = union_into(e.seen.take(), theirs.clone(), max_vertices);
        e.confirmed = union_into(e.confirmed.take(), theirs, max_vertices);
        e.shape = shown(e.seen.as_ref(), e.latest.as_ref(), max_vertices).unwrap_or(e.shape.clone());
        e.uncertainty = e.uncertainty.fused_with(&o.uncertainty);
        refit(e, &o.moments, o.observations);
        self.file(id);
    }

    /// Entry `id` out of the map, its index and its labels.
    fn remove(&mut self, id: u64) -> Option<Entry> {
        self.unfile(id);
        self.label_table.remove(id);
        self.entries.remove(&id)
    }

    /// Entry `id` into the spatial index and the label table, as it is now.
    fn file(&mut self, id: u64) {
        let e = &self.entries[&id];
        self.index.insert(indexed(id, &e.aabb));
        self.label_table.set(id, e.facts);
    }

    /// Entry `id` out of the spatial index before it changes (its box with it).
    fn unfile(&mut self, id: u64) {
        if let Some(e) = self.entries.get(&id) {
            self.index.remove(&indexed(id, &e.aabb));
        }
    }

    /// Labels every entry; returns the ids whose label or step changed.
    fn relabel(&mut self) -> Vec<u64> {
        let (changed, stair) = self.label_table.relabel();
        self.stair = stair;
        for id in &changed {
            self.entries.get_mut(id).expect("the label table holds the entries").published = None;
        }
        changed
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

    /// The whole map.
    pub fn snapshot(&mut self) -> MapSnapshot {
        let polygons = self.ids().into_iter().filter_map(|id| self.polygon(id)).collect();
        MapSnapshot {
            version: self.version,
            frame: "world".into(),
            drift_z: self.drift.z,
            drift_var: self.drift.var,
            stair: self.stair.clone(),
            polygons,
        }
    }

    /// A map rebuilt from a snapshot: each polygon's moments are its surface's, weighted by
    /// its observations, so later frames refine it as if it had been seen all along.
    pub fn from_snapshot(cfg: &MapConfig, s: &MapSnapshot) -> Result<PolygonMap, SnapshotProblem> {
        if s.frame != "world" {
            return Err(SnapshotProblem::Frame(s.frame.clone()));
        }
        if !(s.drift_z.is_finite() && s.drift_var.is_finite() && s.drift_var >= 0.0) {
            return Err(SnapshotProblem::Drift { z: s.drift_z, var: s.drift_var });
        }
        let mut map = PolygonMap::new(cfg);
        map.drift.z = s.drift_z;
        map.drift.var = s.drift_var;
        let mut ids: Vec<u64> = s.polygons.iter().map(|p| p.id).collect();
        ids.sort_unstable();
        if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
            return Err(SnapshotProblem::DuplicateId(w[0]));
        }
        for p in &s.polygons {
            let normal = Vector3::from(p.normal);
            let as_frame_polygon = Polygon {
                id: p.id as u32,
                normal: p.normal,
                offset: p.offset,
                area: p.area,
                boundary: p.boundary.clone(),
                holes: p.holes.clone(),
                boundary_kinds: vec![VertexKind::Inside; p.boundary.len()],
                hole_kinds: p.holes.iter().map(|h| vec![VertexKind::Inside; h.len()]).collect(),
                pixel_count: 0,
                inlier_ratio: 1.0,
                rms: 0.0,
                uncertainty: Default::default(),
            };
            if let Some(problem) = polygon_problem(&as_frame_polygon) {
                return Err(SnapshotProblem::Polygon(Rejection::Polygon { id: p.id, problem }));
            }
            let surface = Moments::of_polygon(&p.boundary, &p.holes, &normal);
            let uncertainty = snapshot_uncertainty(p);
            // Weighted as the observations it fuses were: its fused covariance is their
            // information summed; without one, as many surfaces as it had observations.
            let moments = surface.scaled(if uncertainty.is_known() {
                observation_weight(&uncertainty, &surface)
            } else {
                p.observations.max(1) as f64
            });
            let o = Observation {
                aabb: aabb(&p.boundary),
                plane: Plane { normal, offset: p.offset },
                moments,
                uncertainty,
                horizontal: false,
                erode: vec![0.0; p.boundary.len()],
                erode_holes: p.holes.iter().map(|h| vec![0.0; h.len()]).collect(),
                boundary: p.boundary.clone(),
                holes: p.holes.clone(),
                view: None,
            };
            map.insert(p.id, &o);
            let e = map.entries.get_mut(&p.id).expect("just inserted");
            e.observations = p.observations.max(1);
            e.confirmed = Some(e.shape.clone());
            e.seen = Some(e.shape.clone());
        }
        map.next_id = s.polygons.iter().map(|p| p.id + 1).max().unwrap_or(1);
        map.version = s.version;
        map.relabel();
        Ok(map)
    }
}

/// `acc` grown by `more` (`more` alone when `acc` is empty), simplified.
fn union_into(acc: Option<Shape<f64>>, more: Shape<f64>, max_vertices: usize) -> Option<Shape<f64>> {
    let u = match acc {
        Some(a) => geometry::union(&a, &more).unwrap_or(a),
        None => more,
    };
    Some(geometry::simplify_to(&u, max_vertices))
}

/// `acc` after a frame that looked at `looked` and saw `view`: what it looked at and did not
/// see is gone (except what `keep` holds), and what it saw is added.
fn looked_again(
    acc: Option<Shape<f64>>,
    looked: Option<&Shape<f64>>,
    view: Shape<f64>,
    keep: Option<&Shape<f64>>,
    max_vertices: usize,
) -> Option<Shape<f64>> {
    let acc = match (acc, looked) {
        (Some(a), Some(looked)) => {
            let mut missed = looked.difference(&view);
            if let Some(k) = keep {
                missed = missed.difference(k);
            }
            geometry::difference(&a, &missed)
        }
        (acc, _) => acc,
    };
    union_into(acc, view, max_vertices)
}

/// The shape a map polygon shows: what frames saw and the latest frame's view.
fn shown(seen: Option<&Shape<f64>>, latest: Option<&Shape<f64>>, max_vertices: usize) -> Option<Shape<f64>> {
    let s = match (seen, latest) {
        (Some(c), Some(l)) => geometry::union(c, l)?,
        (Some(s), None) | (None, Some(s)) => s.clone(),
        (None, None) => return None,
    };
    Some(geometry::simplify_to(&s, max_vertices))
}

/// A frame's outline is uncertain by about this many pixel footprints: its edge pixels are
/// mixed, closed over, or belong to the neighbouring surface within the inlier distance, and
/// ray-cast at a grazing angle each lands a whole footprint away. A union would keep every
/// frame's overshoot, so each outline vertex is pulled in by this many footprints where it
/// was seen before it is kept for good; the nearest views, whose footprints are smallest,
/// then set the map's edges. Edges the extractor cut at a neighbour's plane are exact and
/// are not pulled in.
const OUTLINE_UNCERTAINTY_PX: f64 = 1.5;
/// Where an outline runs along the image's border it is where the view ends, not the
/// surface: the pixels there have no normals to check them and no neighbour beyond to
/// stop their region growing over the next surface's first centimetre, seen at the
/// most grazing angle of the frame. Pulled in further; other views see past it.
const VIEW_EDGE_UNCERTAINTY_PX: f64 = 4.0;
/// A frame looked at what lies this many pixels inside its image's border: its outlines
/// along the border (extract::BORDER_PX) are pulled in by less, so missing there is not
/// having looked.
const LOOKED_MARGIN_PX: f64 = crate::extract::polygon::BORDER_PX as f64 + VIEW_EDGE_UNCERTAINTY_PX + 2.0;
/// The most an outline is pulled in, m.
const MAX_ERODE_M: f64 = 0.05;

/// Size of one pixel on the polygon's plane at its vertex `v` (camera frame), m: range
/// over focal length, stretched by the obliquity of the view there.
fn footprint(v: &[f64; 3], p: &Polygon, intrinsics: &Intrinsics) -> f64 {
    let v = Vector3::from(*v);
    v.norm_squared() / (intrinsics.fx * Vector3::from(p.normal).dot(&v).abs().max(1e-6))
}

/// Adds observations' moments to an entry, refits its plane and refreshes what follows.
fn refit(e: &mut Entry, moments: &Moments, observations: u32) {
    e.moments.add(moments);
    e.observations += observations;
    if let Some(p) = e.moments.plane(&e.plane.normal) {
        e.plane = p;
    }
    refresh(e);
}

/// Area, centroid, world box, depth and clearing samples of an entry after its shape or plane changed.
fn refresh(e: &mut Entry) {
    e.published = None;
    e.area = e.shape.unsigned_area();
    let c = e.shape.centroid().map_or(Coord { x: 0.0, y: 0.0 }, |p| p.0);
    e.centroid = e.frame.lift(c, &e.plane);
    e.aabb = aabb(&e.frame.lift_ring(e.shape.exterior(), &e.plane));
    e.facts = labels::Facts {
        tilt_deg: e.plane.normal.z.abs().clamp(0.0, 1.0).acos().to_degrees(),
        height: e.centroid[2],
        z_range: [e.aabb[0][2], e.aabb[1][2]],
        // The width of the smallest rectangle enclosing the shape: a tread's depth.
        depth: e.shape.minimum_rotated_rect().map_or(0.0, |r| min_side(&r)),
        xy: [e.centroid[0], e.centroid[1]],
    };
    e.samples.clear();
    if let Some(r) = geo::BoundingRect::bounding_rect(&e.shape) {
        // A grid of about CLEAR_SAMPLES points over the shape, never finer than 1 cm nor
        // more than MAX_SAMPLE_GRID across: a thin shape in a wide box stays bounded.
        let (w, h) = (r.width(), r.height());
        let step = (e.area / CLEAR_SAMPLES).sqrt().max(0.01).max(w.max(h) / MAX_SAMPLE_GRID);
        if step.is_finite() && step > 0.0 {
            let (nx, ny) = ((w / step).ceil() as usize, (h / step).ceil() as usize);
            for j in 0..ny.min(MAX_SAMPLE_GRID as usize) {
                for i in 0..nx.min(MAX_SAMPLE_GRID as usize) {
                    let c = Coord { x: r.min().x + (i as f64 + 0.5) * step, y: r.min().y + (j as f64 + 0.5) * step };
                    if e.shape.contains(&Point(c)) {
                        e.samples.push(c);
                    }
                }
            }
        }
    }
}

/// Whether the depth image contradicts entry `e` (None: too little of it in view to say).
fn contradiction(
    e: &Entry,
    t_world_camera: &Isometry3<f64>,
    depth_m: &Grid<f32>,
    intrinsics: &Intrinsics,
    cfg: &MapConfig,
) -> Option<bool> {
    // Only a surface's seen side can be judged: a tread from below, or any plane seen
    // edge-on, says nothing.
    let camera = t_world_camera.translation.vector;
    if e.plane.normal.dot(&camera) + e.plane.offset <= 0.0 {
        return None;
    }
    let camera_world = t_world_camera.inverse();
    let (w, h) = (depth_m.width, depth_m.height);
    let (mut support, mut against) = (0usize, 0usize);
    for c in &e.samples {
        let world = Vector3::from(e.frame.lift(*c, &e.plane));
        let ray = world - camera;
        if e.plane.normal.dot(&ray).abs() < MIN_VIEW_COS * ray.norm() {
            continue;
        }
        let p = camera_world * Point3::from(world);
        if p.z < 0.1 {
            continue;
        }
        let (u, v) = intrinsics.project(&p);
        let (u, v) = (u.round(), v.round());
        if u < 0.0 || v < 0.0 || u >= w as f64 || v >= h as f64 {
            continue;
        }
        let measured = depth_m.data[v as usize * w + u as usize] as f64;
        if measured <= 0.0 {
            continue;
        }
        let tol = cfg.clear_tolerance_m + 0.01 * p.z;
        if (measured - p.z).abs() <= tol {
            support += 1;
        } else if measured > p.z || stands_on(e, t_world_camera, &(p * (measured / p.z))) {
            // Seen through it, or something else stands in its place.
            against += 1;
        }
        // Else something nearer hides it (the next step's nosing, a leg): that says nothing.
    }
    (support + against >= MIN_CLEAR_SAMPLES).then_some(against * 2 > support + against)
}

/// Whether a measured point (camera frame) stands on entry `e`: over its footprint, on the
/// camera's side of its plane, less than `OCCLUDER_M` from it. A foot on a tread or a box
/// on the floor does; the next step's riser hiding part of a tread does not.
fn stands_on(e: &Entry, t_world_camera: &Isometry3<f64>, measured: &Point3<f64>) -> bool {
    let w = t_world_camera * measured;
    // The camera is on the plane's positive side (checked before).
    let height = e.plane.normal.dot(&w.coords) + e.plane.offset;
    height > 0.0 && height < OCCLUDER_M && e.shape.contains(&Point(e.frame.to_2d(&[w.x, w.y, w.z])))
}

/// The planner's view of an entry.
fn publish(id: u64, e: &Entry, (label, step): labels::Labelled, foot_margin: f64) -> MapPolygon {
    let lift_ring = |r: &geo::LineString<f64>| e.frame.lift_ring(r, &e.plane);
    let inset_shapes = geometry::inset(&e.shape, foot_margin);
    let convex_pieces = inset_shapes
        .iter()
        .flat_map(convex::convex_pieces)
        .map(|ring| ring.into_iter().map(|c| e.frame.lift(c, &e.plane)).collect())
        .collect();
    let region = |s: &Shape<f64>| Region {
        boundary: lift_ring(s.exterior()),
        holes: s.interiors().iter().map(lift_ring).collect(),
    };
    let n = e.plane.normal;
    MapPolygon {
        id,
        label,
        normal: [n.x, n.y, n.z],
        offset: e.plane.offset,
        // The shape lies on the frame's plane; tilting onto the fitted plane stretches it.
        area: e.area / n.dot(&e.frame.normal).abs().max(1e-6),
        centroid: e.centroid,
        boundary: lift_ring(e.shape.exterior()),
        holes: e.shape.interiors().iter().map(lift_ring).collect(),
        convex_pieces,
        insets: inset_shapes.iter().map(region).collect(),
        observations: e.observations,
        step,
        plane_covariance: plane_covariance(&e.uncertainty, &n, e.centroid),
    }
}

/// The fused plane covariance as planners get it: about the polygon's centroid, with axes
/// in its current plane (the fit has moved since the first observation), as the
/// covariance of the plane's coefficients; all zero when unknown.
fn plane_covariance(u: &PlaneUncertainty, normal: &Vector3<f64>, centroid: [f64; 3]) -> [f64; 16] {
    if !u.is_known() {
        return unknown_covariance();
    }
    let e1 = Vector3::from(u.axes[0]);
    let Some(f1) = (e1 - normal * e1.dot(normal)).try_normalize(1e-9) else { return unknown_covariance() };
    let f2 = normal.cross(&f1);
    u.expressed_at(centroid, [f1.into(), f2.into()]).coefficient_covariance()
}

/// A snapshot polygon's plane uncertainty, from the coefficient covariance it was saved
/// with (about its centroid, on axes of its plane); unknown if it was saved without.
fn snapshot_uncertainty(p: &MapPolygon) -> PlaneUncertainty {
    let (Some([e1, e2]), true) =
        (in_plane_axes(&Vector3::from(p.normal)), p.plane_covariance.iter().all(|c| c.is_finite()))
    else {
        return PlaneUncertainty::default();
    };
    let u = PlaneUncertainty::from_coefficient_covariance(&p.plane_covariance, p.centroid, [e1.into(), e2.into()]);
    if u.is_known() { u } else { PlaneUncertainty::default() }
}

/// The variance, m^2, that counts as one unit of weight: an observation whose plane is
/// known to 1 mm over its surface weighs 1.
const UNIT_WEIGHT_VARIANCE_M2: f64 = 1e-6;
/// Below this variance (10 um) a plane is as well known as any: noise-free synthetic
/// planes would otherwise weigh without bound.
const MIN_WEIGHT_VARIANCE_M2: f64 = 1e-10;

/// What an observation's surface moments are scaled by, so that its total weight is its
/// plane's information: 1 over the variance of the plane's position averaged over the
/// surface (shift and tilts at their lever arms, extract::uncertainty), in units of
/// `UNIT_WEIGHT_VARIANCE_M2`. A far or grazing view, whose plane is noisier, counts less
/// than a near one of the same surface. Unknown uncertainty (hand-made polygons): 1, the
/// surface's area, as before weights.
fn observation_weight(u: &PlaneUncertainty, surface: &Moments) -> f64 {
    if !u.is_known() || !(surface.weight > 0.0) {
        return 1.0;
    }
    let centre = surface.sum / surface.weight;
    let lever_sq = (surface.sum_sq / surface.weight - centre * centre.transpose()).trace().max(0.0);
    let variance = u.expressed_at(centre.into(), u.axes).mean_offset_variance(lever_sq);
    if !variance.is_finite() {
        return 1.0;
    }
    UNIT_WEIGHT_VARIANCE_M2 / variance.max(MIN_WEIGHT_VARIANCE_M2) / surface.weight
}

fn aabb(points: &[[f64; 3]]) -> [[f64; 3]; 2] {
    let mut b = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
    for p in points {
        for k in 0..3 {
            b[0][k] = b[0][k].min(p[k]);
            b[1][k] = b[1][k].max(p[k]);
        }
    }
    b
}

/// An entry in the spatial index: its world box and id.
type Indexed = GeomWithData<Rectangle<[f64; 3]>, u64>;

fn indexed(id: u64, aabb: &[[f64; 3]; 2]) -> Indexed {
    GeomWithData::new(Rectangle::from_corners(aabb[0], aabb[1]), id)
}

/// The world box around everything a frame's depth image can judge: the pyramid of its
/// image out to the farthest depth at which a map polygon's sample can still count for or
/// against it. Support needs the sample within `clear_tolerance_m + 1 %` of the measured
/// depth; seen-through needs it beyond the measurement; something standing on it needs
/// the measured point under `OCCLUDER_M` over its plane, which along a ray at least
/// `MIN_VIEW_COS` off the plane is at most `OCCLUDER_M / MIN_VIEW_COS` nearer.
struct ViewBox(AABB<[f64; 3]>);

impl ViewBox {
    /// None when the image holds no valid depth (nothing can be judged).
    fn new(
        t_world_camera: &Isometry3<f64>,
        depth_m: &Grid<f32>,
        intr: &Intrinsics,
        cfg: &MapConfig,
    ) -> Option<ViewBox> {
        let farthest = depth_m.data.iter().copied().filter(|z| z.is_finite()).fold(0.0f32, f32::max) as f64;
        if farthest <= 0.0 {
            return None;
        }
        let reach = ((farthest + cfg.clear_tolerance_m) / 0.99).max(farthest + OCCLUDER_M / MIN_VIEW_COS);
        let (w, h) = (depth_m.width as f64, depth_m.height as f64);
        // Pixel centres round to pixels from -0.5 to w - 0.5: the image's outer corners.
        let corners = [(-0.5, -0.5), (w - 0.5, -0.5), (w - 0.5, h - 0.5), (-0.5, h - 0.5)];
        let far = corners.iter().map(|&(u, v)| t_world_camera * Point3::from(intr.ray(u, v) * reach));
        let apex = t_world_camera * Point3::origin();
        let points: Vec<[f64; 3]> = far.chain([apex]).map(|p| [p.x, p.y, p.z]).collect();
        let b = aabb(&points);
        Some(ViewBox(AABB::from_corners(b[0], b[1])))
    }
}

fn min_side(r: &Shape<f64>) -> f64 {
    let c = &r.exterior().0;
    if c.len() < 3 {
        return 0.0;
    }
    let d = |a: Coord<f64>, b: Coord<f64>| (a.x - b.x).hypot(a.y - b.y);
    d(c[0], c[1]).min(d(c[1], c[2]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rstar::Envelope;

    /// Every point a depth image can judge lies in its view box: the image's outermost
    /// pixels, from the nearest depth to the farthest reach of a judgement.
    #[test]
    fn the_view_box_holds_every_point_the_depth_image_can_judge() {
        let intr = Intrinsics::L515_320X240;
        let cfg = MapConfig::default();
        let pose = crate::synth::path::camera_pose(Point3::new(-2.0, 1.0, 1.5), 0.3, 40f64.to_radians(), 0.0);
        let mut depth = Grid { width: 320, height: 240, data: vec![0.0f32; 320 * 240] };
        assert!(ViewBox::new(&pose, &depth, &intr, &cfg).is_none(), "no depth, nothing to judge");
        depth.data[1000] = 3.0;
        let view = ViewBox::new(&pose, &depth, &intr, &cfg).expect("one valid pixel");
        let reach = 3.0 + OCCLUDER_M / MIN_VIEW_COS;
        for (u, v) in [(-0.5, -0.5), (319.49, -0.5), (319.49, 239.49), (-0.5, 239.49), (160.0, 120.0)] {
            for z in [0.1, 1.0, 3.0, reach - 1e-9] {
                let p = pose * Point3::from(intr.ray(u, v) * z);
                assert!(view.0.contains_point(&[p.x, p.y, p.z]), "pixel ({u}, {v}) at {z} m");
            }
        }
    }
}
