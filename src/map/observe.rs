//! A frame's polygons as observations in the world, and the map polygons each matches.

use super::*;

impl PolygonMap {
    /// The frame's polygons in the world, drift taken out.
    pub(super) fn observations(
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
                    pixels: u32::try_from(w.pixel_count).unwrap_or(u32::MAX),
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
    pub(super) fn matches(&self, o: &Observation) -> Vec<Match> {
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
                out.push(Match { id, area, dz, at: q });
            }
        }
        out
    }
}

/// A frame's outline is uncertain by about this many pixel footprints: its edge pixels are
/// mixed, closed over, or belong to the neighbouring surface within the inlier distance, and
/// ray-cast at a grazing angle each lands a whole footprint away. A union would keep every
/// frame's overshoot, so each outline vertex is pulled in by this many footprints where it
/// was seen before it is kept for good; the nearest views, whose footprints are smallest,
/// then set the map's edges. Edges the extractor cut at a neighbour's plane are exact and
/// are not pulled in.
pub(super) const OUTLINE_UNCERTAINTY_PX: f64 = 1.5;

/// Where an outline runs along the image's border it is where the view ends, not the
/// surface: the pixels there have no normals to check them and no neighbour beyond to
/// stop their region growing over the next surface's first centimetre, seen at the
/// most grazing angle of the frame. Pulled in further; other views see past it.
pub(super) const VIEW_EDGE_UNCERTAINTY_PX: f64 = 4.0;

/// The most an outline is pulled in, m.
pub(super) const MAX_ERODE_M: f64 = 0.05;

/// Size of one pixel on the polygon's plane at its vertex `v` (camera frame), m: range
/// over focal length, stretched by the obliquity of the view there.
pub(super) fn footprint(v: &[f64; 3], p: &Polygon, intrinsics: &Intrinsics) -> f64 {
    let v = Vector3::from(*v);
    v.norm_squared() / (intrinsics.fx * Vector3::from(p.normal).dot(&v).abs().max(1e-6))
}
