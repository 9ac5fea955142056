//! The map as a snapshot (saved and published) and back; `persist` reads and writes them.

use super::*;

impl PolygonMap {
    /// The whole map.
    pub fn snapshot(&mut self) -> MapSnapshot {
        let polygons = self.ids().into_iter().filter_map(|id| self.polygon(id)).collect();
        MapSnapshot {
            version: self.version,
            frame: MapFrame::World,
            drift_z: self.drift.z,
            drift_var: self.drift.var(),
            drift_xy: [self.drift.x, self.drift.y],
            drift_yaw: self.drift.yaw,
            drift_covariance: Some(self.drift.cov),
            stair: self.stair.clone(),
            polygons,
        }
    }

    /// A map rebuilt from a snapshot: each polygon's moments are its surface's, weighted by
    /// its observations, so later frames refine it as if it had been seen all along.
    pub fn from_snapshot(cfg: &MapConfig, s: &MapSnapshot) -> Result<PolygonMap, SnapshotProblem> {
        let finite = [s.drift_z, s.drift_xy[0], s.drift_xy[1], s.drift_yaw].iter().all(|v| v.is_finite())
            && s.drift_covariance.iter().flatten().flatten().all(|v| v.is_finite());
        let variances_ok = match s.drift_covariance {
            Some(c) => (0..4).all(|k| c[k][k] >= 0.0) && c[2][2] == s.drift_var,
            None => true,
        };
        if !(finite && s.drift_var.is_finite() && s.drift_var >= 0.0 && variances_ok) {
            return Err(SnapshotProblem::Drift { z: s.drift_z, var: s.drift_var });
        }
        let mut map = PolygonMap::new(cfg);
        (map.drift.x, map.drift.y, map.drift.z, map.drift.yaw) = (s.drift_xy[0], s.drift_xy[1], s.drift_z, s.drift_yaw);
        map.drift.cov = s.drift_covariance.unwrap_or_else(|| {
            let mut c = [[0.0; 4]; 4];
            c[2][2] = s.drift_var;
            c
        });
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
                footing: p.footing,
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
                pixels: p.pixels,
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

/// A snapshot polygon's plane uncertainty, from the coefficient covariance it was saved
/// with (about its centroid, on axes of its plane); unknown if it was saved without.
pub(super) fn snapshot_uncertainty(p: &MapPolygon) -> PlaneUncertainty {
    let (Some([e1, e2]), true) =
        (in_plane_axes(&Vector3::from(p.normal)), p.plane_covariance.iter().all(|c| c.is_finite()))
    else {
        return PlaneUncertainty::default();
    };
    let u = PlaneUncertainty::from_coefficient_covariance(&p.plane_covariance, p.centroid, [e1.into(), e2.into()]);
    if u.is_known() { u } else { PlaneUncertainty::default() }
}
