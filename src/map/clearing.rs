//! Clearing: map polygons in view that the depth image contradicts (seen through, or
//! something else in their place) for `clear_after_frames` frames in a row go.

use super::*;

impl PolygonMap {
    /// Map polygons in view that this frame did not see and whose place the depth image
    /// contradicts get a miss; `clear_after_frames` misses in a row remove them. Only map
    /// polygons the view can reach are looked at ([`ViewBox`]), so the cost follows what
    /// is in view, not the map's size.
    pub(super) fn clear_contradicted(
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
}

/// `acc` after a frame that looked at `looked` and saw `view`: what it looked at and did not
/// see is gone (except what `keep` holds), and what it saw is added.
pub(super) fn looked_again(
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

/// A frame looked at what lies this many pixels inside its image's border: its outlines
/// along the border (extract::BORDER_PX) are pulled in by less, so missing there is not
/// having looked.
pub(super) const LOOKED_MARGIN_PX: f64 = crate::extract::polygon::BORDER_PX as f64 + VIEW_EDGE_UNCERTAINTY_PX + 2.0;

/// Whether the depth image contradicts entry `e` (None: too little of it in view to say).
pub(super) fn contradiction(
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
pub(super) fn stands_on(e: &Entry, t_world_camera: &Isometry3<f64>, measured: &Point3<f64>) -> bool {
    let w = t_world_camera * measured;
    // The camera is on the plane's positive side (checked before).
    let height = e.plane.normal.dot(&w.coords) + e.plane.offset;
    height > 0.0 && height < OCCLUDER_M && e.shape.contains(&Point(e.frame.to_2d(&[w.x, w.y, w.z])))
}

/// The world box around everything a frame's depth image can judge: the pyramid of its
/// image out to the farthest depth at which a map polygon's sample can still count for or
/// against it. Support needs the sample within `clear_tolerance_m + 1 %` of the measured
/// depth; seen-through needs it beyond the measurement; something standing on it needs
/// the measured point under `OCCLUDER_M` over its plane, which along a ray at least
/// `MIN_VIEW_COS` off the plane is at most `OCCLUDER_M / MIN_VIEW_COS` nearer.
pub(super) struct ViewBox(AABB<[f64; 3]>);

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
