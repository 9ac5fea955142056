//! Map entries and their fusion: observations inserted or merged (shapes united, planes
//! refitted from the weighted moments), entries absorbed and removed, the index and labels
//! kept, and each entry published as planners get it.

use super::*;

impl PolygonMap {
    /// The frame's bookkeeping: what it touched has no misses, the lists of `update` are
    /// sorted and hold each id once (what was added or changed and then removed is only
    /// removed), labels are redone.
    pub(super) fn settle(&mut self, touched: &[u64], update: &mut MapUpdate) {
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

    /// A new entry `id` made of one observation.
    pub(super) fn insert(&mut self, id: u64, o: &Observation) {
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
            most_pixels: o.pixels,
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
    pub(super) fn merge(&mut self, id: u64, o: &Observation) {
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
        e.most_pixels = e.most_pixels.max(o.pixels);
        refit(e, &o.moments, 1);
        self.file(id);
    }

    /// Entry `other` merged into `id` (one observation bridged them), then dropped.
    pub(super) fn absorb(&mut self, id: u64, other: u64) {
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
        e.most_pixels = e.most_pixels.max(o.most_pixels);
        refit(e, &o.moments, o.observations);
        self.file(id);
    }

    /// Entry `id` out of the map, its index and its labels.
    pub(super) fn remove(&mut self, id: u64) -> Option<Entry> {
        self.unfile(id);
        self.label_table.remove(id);
        self.entries.remove(&id)
    }

    /// Entry `id` into the spatial index and the label table, as it is now.
    pub(super) fn file(&mut self, id: u64) {
        let e = &self.entries[&id];
        self.index.insert(indexed(id, &e.aabb));
        self.label_table.set(id, e.facts);
    }

    /// Entry `id` out of the spatial index before it changes (its box with it).
    pub(super) fn unfile(&mut self, id: u64) {
        if let Some(e) = self.entries.get(&id) {
            self.index.remove(&indexed(id, &e.aabb));
        }
    }

    /// Labels every entry; returns the ids whose label or step changed.
    pub(super) fn relabel(&mut self) -> Vec<u64> {
        let (changed, stair) = self.label_table.relabel();
        self.stair = stair;
        for id in &changed {
            self.entries.get_mut(id).expect("the label table holds the entries").published = None;
        }
        changed
    }
}

/// `acc` grown by `more` (`more` alone when `acc` is empty), simplified.
pub(super) fn union_into(acc: Option<Shape<f64>>, more: Shape<f64>, max_vertices: usize) -> Option<Shape<f64>> {
    let u = match acc {
        Some(a) => geometry::union(&a, &more).unwrap_or(a),
        None => more,
    };
    Some(geometry::simplify_to(&u, max_vertices))
}

/// The shape a map polygon shows: what frames saw and the latest frame's view.
pub(super) fn shown(seen: Option<&Shape<f64>>, latest: Option<&Shape<f64>>, max_vertices: usize) -> Option<Shape<f64>> {
    let s = match (seen, latest) {
        (Some(c), Some(l)) => geometry::union(c, l)?,
        (Some(s), None) | (None, Some(s)) => s.clone(),
        (None, None) => return None,
    };
    Some(geometry::simplify_to(&s, max_vertices))
}

/// Adds observations' moments to an entry, refits its plane and refreshes what follows.
pub(super) fn refit(e: &mut Entry, moments: &Moments, observations: u32) {
    e.moments.add(moments);
    e.observations += observations;
    if let Some(p) = e.moments.plane(&e.plane.normal) {
        e.plane = p;
    }
    refresh(e);
}

/// Area, centroid, world box, depth and clearing samples of an entry after its shape or plane changed.
pub(super) fn refresh(e: &mut Entry) {
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

/// The planner's view of an entry.
pub(super) fn publish(id: u64, e: &Entry, (label, step): labels::Labelled, foot_margin: f64) -> MapPolygon {
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
        footing: footing(&e.uncertainty, e.most_pixels as usize),
        pixels: e.most_pixels,
    }
}

/// The fused plane covariance as planners get it: about the polygon's centroid, with axes
/// in its current plane (the fit has moved since the first observation), as the
/// covariance of the plane's coefficients; all zero when unknown.
pub(super) fn plane_covariance(u: &PlaneUncertainty, normal: &Vector3<f64>, centroid: [f64; 3]) -> [f64; 16] {
    if !u.is_known() {
        return unknown_covariance();
    }
    let e1 = Vector3::from(u.axes[0]);
    let Some(f1) = (e1 - normal * e1.dot(normal)).try_normalize(1e-9) else { return unknown_covariance() };
    let f2 = normal.cross(&f1);
    u.expressed_at(centroid, [f1.into(), f2.into()]).coefficient_covariance()
}

/// The variance, m^2, that counts as one unit of weight: an observation whose plane is
/// known to 1 mm over its surface weighs 1.
pub(super) const UNIT_WEIGHT_VARIANCE_M2: f64 = 1e-6;

/// Below this variance (10 um) a plane is as well known as any: noise-free synthetic
/// planes would otherwise weigh without bound.
pub(super) const MIN_WEIGHT_VARIANCE_M2: f64 = 1e-10;

/// What an observation's surface moments are scaled by, so that its total weight is its
/// plane's information: 1 over the variance of the plane's position averaged over the
/// surface (shift and tilts at their lever arms, extract::uncertainty), in units of
/// `UNIT_WEIGHT_VARIANCE_M2`. A far or grazing view, whose plane is noisier, counts less
/// than a near one of the same surface. Unknown uncertainty (hand-made polygons): 1, the
/// surface's area, as before weights.
pub(super) fn observation_weight(u: &PlaneUncertainty, surface: &Moments) -> f64 {
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

pub(super) fn aabb(points: &[[f64; 3]]) -> [[f64; 3]; 2] {
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
pub(super) type Indexed = GeomWithData<Rectangle<[f64; 3]>, u64>;

pub(super) fn indexed(id: u64, aabb: &[[f64; 3]; 2]) -> Indexed {
    GeomWithData::new(Rectangle::from_corners(aabb[0], aabb[1]), id)
}

pub(super) fn min_side(r: &Shape<f64>) -> f64 {
    let c = &r.exterior().0;
    if c.len() < 3 {
        return 0.0;
    }
    let d = |a: Coord<f64>, b: Coord<f64>| (a.x - b.x).hypot(a.y - b.y);
    d(c[0], c[1]).min(d(c[1], c[2]))
}
