//! The global map on hand-made polygons: merging keeps true shapes, the drift filter, labels,
//! convex pieces and insets, snapshots, and bad input.

use geo::{Area, BooleanOps, Coord, LineString, Polygon as Shape};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3, Vector4};
use polymap::config::MapConfig;
use polymap::extract::uncertainty::{Footing, PlaneUncertainty, footing};
use polymap::extract::{Grid, Polygon, VertexKind};
use polymap::map::convex::convex_pieces;
use polymap::map::drift::{self, DriftFilter, DriftNoise, Row};
use polymap::map::geometry::top_down;
use polymap::map::{Label, MapFrame, MapSnapshot, PolygonMap, PolygonProblem, Rejection, SnapshotProblem, persist};
use polymap::types::{Intrinsics, Pose};
use proptest::prelude::*;

/// A pose at one stamp: these frames come without time, so no step of the odometry is looked for.
fn posed(t: &Isometry3<f64>) -> Pose {
    Pose { stamp_ns: 0, transform: *t }
}

/// A camera 2 m up and 2 m back looking 45 deg down along +x, with a wide view (about
/// 125 deg) so sharp (huge focal length) that outlines are pulled in by micrometres only.
fn camera() -> (Isometry3<f64>, Intrinsics) {
    let pose = polymap::synth::path::camera_pose(Point3::new(-2.0, 0.0, 2.0), 0.0, 45f64.to_radians(), 0.0);
    (pose, sharp(4e6, 4e6))
}

/// A pinhole of focal length 1e6 px with a `w` x `h` image centred on its axis.
fn sharp(w: f64, h: f64) -> Intrinsics {
    Intrinsics { width: w as u32, height: h as u32, fx: 1e6, fy: 1e6, cx: w / 2.0, cy: h / 2.0, depth_scale: 0.00025 }
}

/// A horizontal polygon at height `z` with outline `xy` (world), as the camera sees it.
fn seen(xy: &[[f64; 2]], z: f64, pose: &Isometry3<f64>) -> Polygon {
    let world = Polygon {
        id: 0,
        normal: [0.0, 0.0, 1.0],
        offset: -z,
        area: 0.0,
        boundary: xy.iter().map(|&[x, y]| [x, y, z]).collect(),
        holes: vec![],
        boundary_kinds: vec![VertexKind::Inside; xy.len()],
        hole_kinds: vec![],
        pixel_count: 1000,
        inlier_ratio: 1.0,
        rms: 0.001,
        uncertainty: Default::default(),
        footing: Footing::Steppable,
    };
    world.transformed(&pose.inverse())
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<[f64; 2]> {
    vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
}

#[test]
fn overlapping_views_merge_into_their_true_non_convex_union() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    // An L seen as its two arms, each by two frames (a shape joins for good once two frames
    // saw it; one frame's view goes when the next looks there and does not see it).
    let arm_x = rect(0.0, 0.0, 1.0, 0.3);
    let arm_y = rect(0.0, 0.0, 0.3, 1.0);
    for arm in [&arm_x, &arm_x, &arm_y, &arm_y] {
        map.update(&[seen(arm, 0.0, &pose)], &posed(&pose), &intr, None);
    }
    let snap = map.snapshot();
    assert_eq!(snap.polygons.len(), 1, "the arms overlap: one polygon");
    let p = &snap.polygons[0];
    let l_area = 0.3 + 0.3 - 0.09;
    assert!((p.area - l_area).abs() < 1e-4, "area {} is the L's {l_area}, not its hull's", p.area);
    assert_eq!(p.observations, 4);
    // The inset lies 5 cm inside: arms [0.05, 0.95] x [0.05, 0.25] and their mirror.
    assert_eq!(p.insets.len(), 1);
    let inset = ring_area(&p.insets[0].boundary);
    let want = 2.0 * 0.9 * 0.2 - 0.2 * 0.2;
    assert!((inset - want).abs() < 2e-3, "inset area {inset}, expected about {want}");
    assert!(p.convex_pieces.len() >= 2, "an L needs at least two convex pieces");
    let pieces: f64 = p.convex_pieces.iter().map(|r| ring_area(r)).sum();
    assert!((pieces - inset).abs() < 1e-9, "convex pieces cover {pieces} m^2 of the inset's {inset}");
}

/// Area of `part` outside `whole`, m^2.
fn outside(part: &Shape<f64>, whole: &geo::MultiPolygon<f64>) -> f64 {
    geo::MultiPolygon(vec![part.clone()]).difference(whole).unsigned_area()
}

/// A horizontal polygon at height `z` with outline `xy` and `holes` (world), mapped from
/// two frames.
fn mapped(xy: &[[f64; 2]], holes: &[Vec<[f64; 2]>], z: f64) -> polymap::map::MapPolygon {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let mut p = seen(xy, z, &pose);
    p.holes = holes.iter().map(|h| seen(h, z, &pose).boundary).collect();
    p.hole_kinds = holes.iter().map(|h| vec![VertexKind::Inside; h.len()]).collect();
    map.update(&[p.clone()], &posed(&pose), &intr, None);
    map.update(&[p], &posed(&pose), &intr, None);
    let snap = map.snapshot();
    assert_eq!(snap.polygons.len(), 1);
    snap.polygons.into_iter().next().unwrap()
}

#[test]
fn insets_keep_every_piece_and_every_hole_and_convex_pieces_lie_in_them() {
    let margin = MapConfig::default().foot_margin_m;
    // A 1 x 0.6 m tread with a 0.2 m square hole in its middle.
    let hole = rect(0.4, 0.2, 0.6, 0.4);
    let p = mapped(&rect(0.0, 0.0, 1.0, 0.6), std::slice::from_ref(&hole), 0.15);
    assert_eq!(p.holes.len(), 1, "the tread keeps its hole");
    assert_eq!(p.insets.len(), 1, "one inset");
    assert_eq!(p.insets[0].holes.len(), 1, "the inset keeps the hole");
    let inset = top_down(&p.insets[0].boundary, &p.insets[0].holes);
    // The hole grows by the margin (rounded corners), the outline shrinks by it.
    let grown_hole = ring_area(&p.insets[0].holes[0]);
    let square_grown = (0.2 + 2.0 * margin).powi(2);
    let rounded = square_grown - (4.0 - std::f64::consts::PI) * margin * margin;
    assert!((grown_hole - rounded).abs() < 2e-3, "hole grown to {grown_hole} m^2, about {rounded}");
    let want = (1.0 - 2.0 * margin) * (0.6 - 2.0 * margin) - rounded;
    assert!((inset.unsigned_area() - want).abs() < 2e-3, "inset {} m^2, about {want}", inset.unsigned_area());
    // The convex pieces tile the inset, and none reaches into the grown hole.
    let inset_mp = geo::MultiPolygon(vec![inset.clone()]);
    let mut sum = 0.0;
    for piece in &p.convex_pieces {
        let s = top_down(piece, &[]);
        sum += s.unsigned_area();
        assert!(outside(&s, &inset_mp) < 1e-9, "a convex piece leaves the inset");
    }
    assert!((sum - inset.unsigned_area()).abs() < 1e-9, "pieces {sum} m^2");
}

#[test]
fn a_necked_polygon_keeps_both_pieces_of_its_inset() {
    // Two 0.4 m squares joined by a 6 cm neck: the 5 cm margin closes the neck.
    let outline = vec![
        [0.0, 0.0],
        [0.4, 0.0],
        [0.4, 0.17],
        [0.6, 0.17],
        [0.6, 0.0],
        [1.0, 0.0],
        [1.0, 0.4],
        [0.6, 0.4],
        [0.6, 0.23],
        [0.4, 0.23],
        [0.4, 0.4],
        [0.0, 0.4],
    ];
    let p = mapped(&outline, &[], 0.0);
    assert_eq!(
        p.insets.len(),
        2,
        "both squares' insets: {:?}",
        p.insets.iter().map(|r| ring_area(&r.boundary)).collect::<Vec<_>>()
    );
    for r in &p.insets {
        let a = ring_area(&r.boundary);
        assert!((a - 0.3 * 0.3).abs() < 2e-3, "each piece is a 0.3 m square: {a}");
    }
    let x_extent = |r: &polymap::map::Region| {
        r.boundary.iter().fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v[0]), hi.max(v[0])))
    };
    let extents: Vec<(f64, f64)> = p.insets.iter().map(x_extent).collect();
    assert!(
        extents.iter().any(|&(_, hi)| hi < 0.4) && extents.iter().any(|&(lo, _)| lo > 0.6),
        "one each side: {extents:?}"
    );
}

#[test]
fn the_foothold_answer_lies_inside_the_inset() {
    use polymap::map::foothold::foothold;
    let hole = rect(0.4, 0.2, 0.6, 0.4);
    let p = mapped(&rect(0.0, 0.0, 1.0, 0.6), std::slice::from_ref(&hole), 0.15);
    let inset = geo::MultiPolygon(p.insets.iter().map(|r| top_down(&r.boundary, &r.holes)).collect());
    let snap = MapSnapshot {
        version: 1,
        frame: MapFrame::World,
        drift_z: 0.0,
        drift_var: 0.0,
        drift_xy: [0.0; 2],
        drift_yaw: 0.0,
        drift_covariance: None,
        stair: None,
        polygons: vec![p],
    };
    // Beside the hole, in the hole, near the outline (inside the polygon but not the inset),
    // and off the polygon.
    for (q, inside) in [([0.2, 0.3], true), ([0.5, 0.3], false), ([0.98, 0.3], false), ([1.3, 0.3], false)] {
        let f = foothold(&snap, [q[0], q[1], 0.2]).expect("a foothold");
        let piece = top_down(&f.piece, &[]);
        assert!(piece.unsigned_area() > 0.01, "at {q:?}: a region a foot fits in, {} m^2", piece.unsigned_area());
        assert!(
            outside(&piece, &inset) < 1e-9,
            "at {q:?}: the region leaves the inset by {} m^2",
            outside(&piece, &inset)
        );
        assert_eq!(f.distance == 0.0, inside, "at {q:?}: distance {}", f.distance);
        assert!(f.piece.iter().all(|v| (v[2] - 0.15).abs() < 1e-9), "on the tread's plane");
        if inside {
            use geo::Contains;
            assert!(piece.contains(&geo::Point::new(q[0], q[1])), "the region holds the point");
            // The largest convex region round (0.2, 0.3) beside the hole: the inset's strip
            // between its outline and the grown hole, 0.3 x 0.5 m.
            assert!(piece.unsigned_area() > 0.99 * 0.3 * 0.5, "{} m^2", piece.unsigned_area());
        }
    }
}

#[test]
fn what_one_frame_saw_stays_until_a_later_frame_looks_there_and_does_not_see_it() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let tread = rect(0.0, 0.0, 0.28, 1.0);
    map.update(&[seen(&tread, 0.15, &pose)], &posed(&pose), &intr, None);
    // One frame's leak 10 cm past the back edge.
    map.update(&[seen(&rect(0.0, 0.0, 0.38, 1.0), 0.15, &pose)], &posed(&pose), &intr, None);
    assert!((map.snapshot().polygons[0].area - 0.38).abs() < 1e-4, "the latest view shows");
    // A camera 1 m over the tread looking straight down sees x in -0.08..0.22 only: the
    // tread's front, not the leak's place.
    let down = polymap::synth::path::camera_pose(Point3::new(0.07, 0.5, 1.15), 0.0, 90f64.to_radians(), 0.0);
    map.update(&[seen(&rect(0.0, 0.0, 0.22, 1.0), 0.15, &down)], &posed(&down), &sharp(1.2e6, 3e5), None);
    let area = map.snapshot().polygons[0].area;
    assert!((area - 0.38).abs() < 1e-4, "a frame that did not look there says nothing of it: area {area}");
    // A frame that looks at the whole tread and sees no leak there.
    map.update(&[seen(&tread, 0.15, &pose)], &posed(&pose), &intr, None);
    let area = map.snapshot().polygons[0].area;
    assert!((area - 0.28).abs() < 1e-4, "the leak seen once is gone: area {area}");
}

#[test]
fn outlines_are_pulled_in_by_what_their_vertices_lie_on_and_not_at_all_along_a_cut() {
    // An L515-like focal length: a pixel spans centimetres on the tread at this distance.
    let (pose, _) = camera();
    let intr = Intrinsics::L515_320X240;
    // The tread's back edge (vertices 1 and 2, x = 0.28) of the given kind, the rest Inside.
    let tread = |x0: f64, x1: f64, back: VertexKind| {
        let mut p = seen(&rect(x0, 0.0, x1, 1.0), 0.15, &pose);
        p.boundary_kinds[1] = back;
        p.boundary_kinds[2] = back;
        p
    };
    // The riser behind the tread: its plane meets the tread's back edge, whatever its kinds.
    let riser = Polygon {
        id: 1,
        normal: [-1.0, 0.0, 0.0],
        offset: 0.28,
        area: 0.15,
        boundary: vec![[0.28, 0.0, 0.15], [0.28, 1.0, 0.15], [0.28, 1.0, 0.3], [0.28, 0.0, 0.3]],
        holes: vec![],
        boundary_kinds: vec![VertexKind::Inside; 4],
        hole_kinds: vec![],
        pixel_count: 1000,
        inlier_ratio: 1.0,
        rms: 0.001,
        uncertainty: Default::default(),
        footing: polymap::extract::Footing::Steppable,
    }
    .transformed(&pose.inverse());
    let back_edge_kept = |back: VertexKind| {
        let mut map = PolygonMap::new(&MapConfig::default());
        for _ in 0..2 {
            map.update(&[tread(0.0, 0.28, back), riser.clone()], &posed(&pose), &intr, None);
        }
        // A last, small view of the tread's middle, so the map shows what it keeps for good.
        map.update(&[tread(0.1, 0.2, VertexKind::Inside), riser.clone()], &posed(&pose), &intr, None);
        let snap = map.snapshot();
        let kept = snap.polygons.iter().find(|p| p.normal[2] > 0.9).expect("the tread is mapped");
        let xs = kept.boundary.iter().map(|v| v[0]);
        let (x0, x1) = xs.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
        assert!(x0 > 0.005, "the front edge, a pixel outline, is pulled in: x {x0}");
        x1
    };
    let cut = back_edge_kept(VertexKind::Cut { neighbour: Some(1) });
    assert!((cut - 0.28).abs() < 1e-6, "the cut back edge stays at the riser: x {cut}");
    // The same vertices on the riser's plane, said to be a pixel outline, are pulled in:
    // the kinds decide, not where the vertices happen to lie.
    let inside = back_edge_kept(VertexKind::Inside);
    assert!(inside < 0.28 - 0.005, "a pixel outline is pulled in: x {inside}");
    // Along the image's border, further.
    let border = back_edge_kept(VertexKind::ImageBorder);
    assert!(border < inside - 0.005, "the view's edge is pulled in further: x {border} vs {inside}");
}

#[test]
fn a_polygon_whose_vertex_kinds_do_not_match_its_vertices_is_refused_with_why() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let mut p = seen(&rect(0.0, 0.0, 1.0, 1.0), 0.0, &pose);
    p.boundary_kinds.pop();
    let update = map.update(&[p], &posed(&pose), &intr, None);
    assert!(map.is_empty());
    assert_eq!(update.rejected.len(), 1);
    assert!(
        matches!(
            update.rejected[0],
            Rejection::Polygon { problem: PolygonProblem::KindsMismatch { outline_kinds: 3, outline: 4, .. }, .. }
        ),
        "{:?}",
        update.rejected
    );
    assert!(update.rejected[0].to_string().contains("3 kinds for the outline's 4 vertices"), "{:?}", update.rejected);
    assert_eq!(map.counters.rejected, 1);
}

#[test]
fn polygons_at_different_heights_or_tilts_stay_apart() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let r = rect(0.0, 0.0, 1.0, 1.0);
    // 15 cm apart (two treads), beyond the 5 cm drift tolerance.
    map.update(&[seen(&r, 0.0, &pose), seen(&r, 0.15, &pose)], &posed(&pose), &intr, None);
    assert_eq!(map.len(), 2);
    // 3 cm apart: the same surface.
    map.update(&[seen(&r, 0.03, &pose)], &posed(&pose), &intr, None);
    assert_eq!(map.len(), 2);
    // Tilted 30 deg, beyond the 10 deg normal tolerance.
    let mut tilted = seen(&r, 0.0, &pose);
    let n = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians()) * Vector3::from(tilted.normal);
    tilted.normal = [n.x, n.y, n.z];
    map.update(&[tilted], &posed(&pose), &intr, None);
    assert_eq!(map.len(), 3);
}

#[test]
fn plane_is_refit_from_all_observations() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig { drift_filter: false, ..MapConfig::default() });
    let r = rect(0.0, 0.0, 1.0, 1.0);
    for z in [0.10, 0.12, 0.14] {
        map.update(&[seen(&r, z, &pose)], &posed(&pose), &intr, None);
    }
    let p = &map.snapshot().polygons[0];
    assert!((p.offset + 0.12).abs() < 1e-9, "plane height {} is the mean 0.12", -p.offset);
    assert!((p.normal[2] - 1.0).abs() < 1e-12);
}

/// Variance of the distance to a plane at point `x`, from its coefficient covariance.
fn distance_variance(c: &[f64; 16], x: [f64; 3]) -> f64 {
    let v = [x[0], x[1], x[2], 1.0];
    (0..4).map(|r| (0..4).map(|k| v[r] * c[4 * r + k] * v[k]).sum::<f64>()).sum()
}

#[test]
fn the_map_s_plane_covariance_is_its_observations_fused_and_shrinks_as_they_come_in() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    // A tread seen by its extractor with 1 mm of offset sigma and 0.2 deg of tilt sigma
    // (about its own centre, with axes of its own): as a frame polygon carries it.
    let world_uncertainty = PlaneUncertainty {
        centre: [0.4, 0.1, 0.2],
        axes: [[0.6, 0.8, 0.0], [-0.8, 0.6, 0.0]],
        cov: [[1.2e-5, 2e-6, 1e-7], [2e-6, 1.0e-5, -2e-7], [1e-7, -2e-7, 1e-6]],
    };
    let mut tread = seen(&rect(0.0, -0.5, 0.8, 0.5), 0.2, &pose);
    tread.uncertainty = world_uncertainty.moved(
        |v| (pose.inverse().rotation * Vector3::from(v)).into(),
        |v| (pose.inverse() * Point3::from(v)).coords.into(),
    );
    let mut variances = Vec::new();
    for k in 1..=8 {
        map.update(std::slice::from_ref(&tread), &posed(&pose), &intr, None);
        let snap = map.snapshot();
        assert_eq!(snap.polygons.len(), 1);
        let p = &snap.polygons[0];
        assert_eq!(p.observations, k);
        let c = p.plane_covariance;
        // Symmetric, and a proper covariance along the plane's own directions.
        for r in 0..4 {
            for q in 0..4 {
                assert!((c[4 * r + q] - c[4 * q + r]).abs() <= 1e-15, "symmetric: {c:?}");
            }
        }
        variances.push(distance_variance(&c, p.centroid));
    }
    // One observation: the extractor's own variance, moved to the map polygon's centroid.
    let centroid = map.snapshot().polygons[0].centroid;
    let d = Vector3::from(centroid) - Vector3::from(world_uncertainty.centre);
    let (a, b) = (d.dot(&Vector3::from(world_uncertainty.axes[0])), d.dot(&Vector3::from(world_uncertainty.axes[1])));
    let g = [-a, -b, 1.0];
    let cov = world_uncertainty.cov;
    let want = (0..3).map(|r| (0..3).map(|q| g[r] * cov[r][q] * g[q]).sum::<f64>()).sum::<f64>();
    assert!((variances[0] - want).abs() <= 1e-9 * want, "first observation: {} against {want}", variances[0]);
    // Equal independent observations: information adds, the variance falls as 1 / k.
    for (k, v) in variances.iter().enumerate() {
        let expected = variances[0] / (k + 1) as f64;
        assert!((v - expected).abs() <= 1e-6 * expected, "after {} observations: {v} against {expected}", k + 1);
    }
    // A polygon that says nothing of its plane adds nothing.
    let mut unknown = tread.clone();
    unknown.uncertainty = PlaneUncertainty::default();
    map.update(&[unknown], &posed(&pose), &intr, None);
    let p = &map.snapshot().polygons[0];
    assert_eq!(p.observations, 9);
    let v = distance_variance(&p.plane_covariance, p.centroid);
    assert!((v - variances[7]).abs() <= 1e-6 * v, "an unknown covariance changed the fused one: {v}");
}

/// A horizontal tread over x 0..0.8, y -0.5..0.5 at height `z`, its plane known to
/// `sigma_m` at its centre (tilts known to 1e-6 rad: their lever arms add nothing).
fn tread_known_to(z: f64, sigma_m: f64, pose: &Isometry3<f64>) -> Polygon {
    let mut tread = seen(&rect(0.0, -0.5, 0.8, 0.5), z, pose);
    let world = PlaneUncertainty {
        centre: [0.4, 0.0, z],
        axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        cov: [[1e-12, 0.0, 0.0], [0.0, 1e-12, 0.0], [0.0, 0.0, sigma_m * sigma_m]],
    };
    tread.uncertainty = world.moved(
        |v| (pose.inverse().rotation * Vector3::from(v)).into(),
        |v| (pose.inverse() * Point3::from(v)).coords.into(),
    );
    tread
}

/// A tread over x 0..0.8, y -0.5..0.5 at height 0.2 seen by `pixels` pixels, its tilt known
/// to `sigma_deg` along each axis, judged by the footing rule as the extractor judges it.
fn tread_tilt_known_to(sigma_deg: f64, pixels: usize, pose: &Isometry3<f64>) -> Polygon {
    let mut tread = seen(&rect(0.0, -0.5, 0.8, 0.5), 0.2, pose);
    let s = sigma_deg.to_radians();
    let world = PlaneUncertainty {
        centre: [0.4, 0.0, 0.2],
        axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        cov: [[s * s, 0.0, 0.0], [0.0, s * s, 0.0], [0.0, 0.0, 1e-6]],
    };
    tread.uncertainty = world.moved(
        |v| (pose.inverse().rotation * Vector3::from(v)).into(),
        |v| (pose.inverse() * Point3::from(v)).coords.into(),
    );
    tread.pixel_count = pixels;
    tread.footing = footing(&tread.uncertainty, pixels);
    tread
}

#[test]
fn a_map_polygon_becomes_steppable_as_observations_shrink_its_covariance() {
    use polymap::map::foothold::foothold;
    let (pose, intr) = camera();
    let on_it = [0.4, 0.0, 0.2];
    // Each frame knows its tilt to 0.6 deg (1.18 deg at 95 %): over the bar, alone.
    let tread = tread_tilt_known_to(0.6, 1000, &pose);
    assert_eq!(tread.footing, Footing::TiltUnknown);
    let mut map = PolygonMap::new(&MapConfig::default());
    map.update(std::slice::from_ref(&tread), &posed(&pose), &intr, None);
    let snap = map.snapshot();
    assert_eq!(snap.polygons[0].footing, Footing::TiltUnknown);
    assert!(foothold(&snap, on_it).is_none(), "no foothold on a plane not known");
    // Two such views: 0.42 deg, 0.83 at 95 %.
    map.update(std::slice::from_ref(&tread), &posed(&pose), &intr, None);
    let snap = map.snapshot();
    assert_eq!((snap.polygons.len(), snap.polygons[0].observations), (1, 2));
    assert_eq!(snap.polygons[0].footing, Footing::Steppable);
    assert!(foothold(&snap, on_it).is_some_and(|f| f.distance == 0.0), "a foothold once it is known");

    // Well known but small in every frame: not steppable however often seen, until one
    // frame sees it whole.
    let (small, whole) = (tread_tilt_known_to(0.1, 150, &pose), tread_tilt_known_to(0.1, 400, &pose));
    let mut map = PolygonMap::new(&MapConfig::default());
    for _ in 0..5 {
        map.update(std::slice::from_ref(&small), &posed(&pose), &intr, None);
    }
    let snap = map.snapshot();
    assert_eq!((snap.polygons[0].footing, snap.polygons[0].pixels), (Footing::FewPixels, 150));
    map.update(std::slice::from_ref(&whole), &posed(&pose), &intr, None);
    let snap = map.snapshot();
    assert_eq!((snap.polygons[0].footing, snap.polygons[0].pixels), (Footing::Steppable, 400));
    // A snapshot keeps what made it steppable.
    let reloaded = PolygonMap::from_snapshot(&MapConfig::default(), &snap).unwrap().snapshot();
    assert_eq!((reloaded.polygons[0].footing, reloaded.polygons[0].pixels), (Footing::Steppable, 400));
}

#[test]
fn the_map_s_plane_weighs_each_observation_by_how_well_its_plane_is_known() {
    let (pose, intr) = camera();
    // No drift filter: it would read the two heights' difference as drift.
    let cfg = MapConfig { drift_filter: false, ..MapConfig::default() };
    // The same tread seen twice, 2 mm apart: once known to 0.2 mm, once to 2 mm.
    let (precise, noisy) = (tread_known_to(0.200, 0.0002, &pose), tread_known_to(0.202, 0.002, &pose));
    // Inverse-variance weights: 25e6 and 0.25e6 per m^2 of variance.
    let (wp, wn) = (1.0 / 0.0002f64.powi(2), 1.0 / 0.002f64.powi(2));
    let want = (0.200 * wp + 0.202 * wn) / (wp + wn);
    for order in [[&precise, &noisy], [&noisy, &precise]] {
        let mut map = PolygonMap::new(&cfg);
        for tread in order {
            map.update(std::slice::from_ref(tread), &posed(&pose), &intr, None);
        }
        let snap = map.snapshot();
        assert_eq!(snap.polygons.len(), 1, "one tread");
        let height = snap.polygons[0].height_at(0.4, 0.0);
        // Weighted by area alone both count the same: 0.201.
        assert!((height - want).abs() < 1e-7, "height {height}, the weighted mean is {want}");
    }
}

#[test]
fn a_snapshot_keeps_the_plane_covariance_and_weight_so_a_reloaded_map_fuses_on_as_if_never_saved() {
    let (pose, intr) = camera();
    let cfg = MapConfig { drift_filter: false, ..MapConfig::default() };
    let mut map = PolygonMap::new(&cfg);
    for (z, sigma) in [(0.200, 0.0005), (0.201, 0.001), (0.1995, 0.0008)] {
        map.update(&[tread_known_to(z, sigma, &pose)], &posed(&pose), &intr, None);
    }
    let saved = map.snapshot();
    let mut reloaded = PolygonMap::from_snapshot(&cfg, &saved).unwrap();
    let again = reloaded.snapshot();
    let (a, b) = (&saved.polygons[0], &again.polygons[0]);
    let v = distance_variance(&a.plane_covariance, a.centroid);
    assert!(v > 0.0, "the saved covariance is known");
    for k in 0..16 {
        assert!((a.plane_covariance[k] - b.plane_covariance[k]).abs() <= 1e-9 * v, "entry {k}: {a:?} vs {b:?}");
    }
    // One more, noisier view: both maps move the same way, the reloaded one weighing what
    // it had as the three views it fused.
    let next = tread_known_to(0.203, 0.0006, &pose);
    map.update(std::slice::from_ref(&next), &posed(&pose), &intr, None);
    reloaded.update(std::slice::from_ref(&next), &posed(&pose), &intr, None);
    let (a, b) = (&map.snapshot().polygons[0], &reloaded.snapshot().polygons[0]);
    let (ha, hb) = (a.height_at(0.4, 0.0), b.height_at(0.4, 0.0));
    assert!((ha - hb).abs() < 2e-6, "heights after one more view: {ha} live, {hb} reloaded");
    assert!(ha > 0.2001 && ha < 0.2015, "the new view moved the plane by its weight: {ha}");
    let (va, vb) =
        (distance_variance(&a.plane_covariance, a.centroid), distance_variance(&b.plane_covariance, b.centroid));
    assert!(va < v && (va - vb).abs() <= 1e-6 * va, "variance {v} -> {va} live, {vb} reloaded");
}

#[test]
fn drift_filter_follows_the_papers_equations_when_only_heights_are_measured() {
    let noise = DriftNoise { horizontal: false, ..DriftNoise::from(&MapConfig::default()) };
    let mut f = DriftFilter::new(noise);
    f.predict(&Vector3::zeros());
    assert_eq!(f.var(), 4e-6);
    // A floor seen 10 mm above the map's, known to 0.1 mm: a measurement of 10 mm with the
    // least variance a frame is allowed (1 mm^2) and its own.
    let floor = |dz: f64| drift::solve(&[Row::point_to_plane(&Vector3::new(1.0, 2.0, 0.0), &Vector3::z(), dz, 1e-8)]);
    f.correct(&floor(0.01));
    let k = 4e-6 / (4e-6 + 1e-6 + 1e-8);
    assert!((f.z - k * 0.01).abs() < 1e-15, "{} against {}", f.z, k * 0.01);
    assert!((f.var() - (1.0 - k) * 4e-6).abs() < 1e-18);
    assert_eq!(f.observed, drift::Z);
    for _ in 0..50 {
        f.predict(&Vector3::zeros());
        f.correct(&floor(0.02 - f.z));
    }
    assert!((f.z - 0.02).abs() < 1e-9, "a constant drift is found: {}", f.z);
    assert_eq!([f.x, f.y, f.yaw], [0.0; 3], "nothing but the height moves");
}

#[test]
fn planes_measure_the_directions_their_normals_span_and_no_other() {
    // The map frame off by 12 mm, -7 mm, 3 mm and 0.4 deg: rows of three perpendicular planes
    // at their overlaps' centroids, and the riser's and the wall's headings.
    let error = Vector4::new(0.012, -0.007, 0.003, 0.4f64.to_radians() * drift::YAW_LEVER_M);
    let dz_of = |q: &Vector3<f64>, n: &Vector3<f64>| {
        let moved =
            q + Vector3::new(error.x, error.y, error.z) + Vector3::z().cross(q) * (error.w / drift::YAW_LEVER_M);
        -n.dot(&(moved - q))
    };
    let plane = |q: Vector3<f64>, n: Vector3<f64>| Row::point_to_plane(&q, &n, dz_of(&q, &n), 1e-6);
    let floor = plane(Vector3::new(0.5, 0.0, 0.0), Vector3::z());
    let riser = plane(Vector3::new(1.0, 0.1, 0.07), Vector3::x());
    let wall = plane(Vector3::new(0.6, 0.8, 0.3), -Vector3::y());
    let heading = Row::heading(0.4f64.to_radians(), 1e-6);
    let all = drift::solve(&[floor, riser, wall, heading]);
    assert_eq!(all.directions.len(), 4);
    assert!((all.error - error).norm() < 1e-9, "{:?} against {error:?}", all.error);
    // A straight stair without walls: nothing along its risers.
    let stair = drift::solve(&[floor, riser, heading, plane(Vector3::new(1.3, -0.2, 0.22), Vector3::x())]);
    assert_eq!(stair.directions.len(), 3);
    assert!(stair.directions.iter().all(|(u, _, _)| u.y.abs() < 1e-9), "y is not observed: {:?}", stair.directions);
    let mut f = DriftFilter::new(DriftNoise::from(&MapConfig::default()));
    f.predict(&Vector3::new(0.0, 0.0, 1.0));
    f.correct(&stair);
    assert_eq!(f.observed, drift::X | drift::Z | drift::YAW);
    // Left to the odometry: only the turn's lever on the x shift moves it, by micrometres.
    assert!(f.y.abs() < 1e-4, "y {}", f.y);
}

/// A vertical face from `a` to `b` (world, seen from above), `z0` to `z1` high, facing left of
/// a -> b, as the camera at `pose` sees it.
fn face(a: [f64; 2], b: [f64; 2], z0: f64, z1: f64, pose: &Isometry3<f64>) -> Polygon {
    let d = Vector3::new(b[0] - a[0], b[1] - a[1], 0.0).normalize();
    let n = Vector3::new(-d.y, d.x, 0.0);
    let boundary = vec![[a[0], a[1], z0], [a[0], a[1], z1], [b[0], b[1], z1], [b[0], b[1], z0]];
    let world = Polygon {
        normal: n.into(),
        offset: -(n.x * a[0] + n.y * a[1]),
        boundary,
        boundary_kinds: vec![VertexKind::Inside; 4],
        ..seen(&rect(0.0, 0.0, 1.0, 1.0), 0.0, &Isometry3::identity())
    };
    world.transformed(&pose.inverse())
}

/// The floor, a riser and a wall in front of the camera: planes with normals in x, y and z.
fn corner(pose: &Isometry3<f64>) -> Vec<Polygon> {
    vec![
        seen(&rect(-1.5, -1.0, 0.5, 0.8), 0.0, pose),
        face([0.5, 0.6], [0.5, -0.6], 0.0, 0.15, pose),
        face([0.9, 0.8], [-1.0, 0.8], 0.0, 0.6, pose),
        seen(&rect(0.5, -0.6, 0.8, 0.6), 0.15, pose),
    ]
}

/// The drift a walk with odometry off by `d` at `k`: D_k = d^k, about the origin.
fn drift_at(k: f64, per_frame: [f64; 4]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(per_frame[0] * k, per_frame[1] * k, per_frame[2] * k),
        UnitQuaternion::from_euler_angles(0.0, 0.0, (per_frame[3] * k).to_radians()),
    )
}

#[test]
fn a_riser_and_a_wall_take_horizontal_and_yaw_drift_out_of_the_map() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let per_frame = [0.0005, -0.0003, 0.0002, 0.01];
    for k in 0..=40 {
        // The planes are where they are; the odometry says the camera is elsewhere.
        let odometry = drift_at(k as f64, per_frame) * pose;
        map.update(&corner(&pose), &posed(&odometry), &intr, None);
    }
    let truth = drift_at(40.0, per_frame);
    let d = &map.drift;
    let t = truth.translation.vector;
    assert!((d.x - t.x).abs() < 1e-3 && (d.y - t.y).abs() < 1e-3 && (d.z - t.z).abs() < 1e-3, "{d:?} against {t:?}");
    // The map's own planes take in a little of each frame's turn before it is measured.
    assert!((d.yaw.to_degrees() - 0.4).abs() < 0.1, "yaw {} deg", d.yaw.to_degrees());
    assert_eq!(d.observed, drift::X | drift::Y | drift::Z | drift::YAW);
    let snap = map.snapshot();
    assert_eq!(snap.polygons.len(), 4, "nothing smeared into a second copy");
    let riser = snap.polygons.iter().find(|p| p.normal[0].abs() > 0.9).unwrap();
    let wall = snap.polygons.iter().find(|p| p.normal[1].abs() > 0.9).unwrap();
    assert!((riser.centroid[0] - 0.5).abs() < 2e-3, "the riser stays at x = 0.5: {:?}", riser.centroid);
    assert!((wall.centroid[1] - 0.8).abs() < 2e-3, "the wall stays at y = 0.8: {:?}", wall.centroid);
    // Without the horizontal filter the same walk moves the riser by the drift.
    let cfg = MapConfig { drift_horizontal: false, ..MapConfig::default() };
    let mut vertical = PolygonMap::new(&cfg);
    for k in 0..=40 {
        vertical.update(&corner(&pose), &posed(&(drift_at(k as f64, per_frame) * pose)), &intr, None);
    }
    let moved = vertical.snapshot();
    let riser = moved.polygons.iter().find(|p| p.normal[0].abs() > 0.9).unwrap();
    assert!((riser.centroid[0] - 0.5).abs() > 5e-3, "the feature is what holds it: {:?}", riser.centroid);
}

#[test]
fn a_wrong_match_does_not_move_the_map() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    // A box the size of a tread beside the stair, its face towards the camera.
    let the_box = |x: f64, pose: &Isometry3<f64>| face([x, -0.2], [x, -0.5], 0.0, 0.3, pose);
    for _ in 0..3 {
        let mut frame = corner(&pose);
        frame.push(the_box(-0.3, &pose));
        map.update(&frame, &posed(&pose), &intr, None);
    }
    let before = map.drift;
    // The box moves 3 cm a frame (within the merge tolerance), and a tread is seen a step up
    // from where it is (a mismatch of steps): neither pulls the drift.
    for k in 1..=5 {
        let mut frame = corner(&pose);
        frame.push(the_box(-0.3 + 0.03 * k as f64, &pose));
        frame.push(seen(&rect(0.5, -0.6, 0.8, 0.6), 0.30, &pose));
        map.update(&frame, &posed(&pose), &intr, None);
    }
    let d = map.drift;
    assert!(
        (d.x - before.x).abs() < 5e-4 && (d.y - before.y).abs() < 5e-4 && (d.z - before.z).abs() < 5e-4,
        "{before:?} -> {d:?}"
    );
    assert!(d.yaw.abs() < 0.01f64.to_radians(), "yaw {} deg", d.yaw.to_degrees());
    assert!(map.counters.registration_outliers > 0, "the box's rows were dropped");
    let riser = map.snapshot().polygons.into_iter().find(|p| p.normal[0].abs() > 0.9 && p.centroid[0] > 0.4).unwrap();
    assert!((riser.centroid[0] - 0.5).abs() < 1e-3, "{:?}", riser.centroid);
}

#[test]
fn a_step_within_the_merge_tolerance_is_registered_away_as_drift() {
    let (start, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    for k in 0..30u64 {
        // Walking 1 cm a frame; from frame 15 the odometry is 3 cm off in x: too small to be
        // taken as a step, within the merge tolerance.
        let pose = Translation3::new(0.01 * k as f64, 0.0, 0.0) * start;
        let odometry = if k >= 15 { Translation3::new(0.03, 0.0, 0.0) * pose } else { pose };
        map.update(&corner(&pose), &Pose { stamp_ns: k * 33_333_333, transform: odometry }, &intr, None);
    }
    assert_eq!(map.counters.odometry_steps, 0);
    assert!((map.drift.x - 0.03).abs() < 2e-3, "drift x {}", map.drift.x);
    let snap = map.snapshot();
    assert_eq!(snap.polygons.len(), 4, "nothing smeared into a second copy");
    let riser = snap.polygons.iter().find(|p| p.normal[0].abs() > 0.9).unwrap();
    assert!((riser.centroid[0] - 0.5).abs() < 3e-3, "{:?}", riser.centroid);
}

#[test]
fn a_step_of_the_odometry_is_taken_into_the_drift_not_the_map() {
    let (start, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let (step_m, step_deg) = (0.08, 1.0f64);
    let mut stepped_at = Vec::new();
    for k in 0..30u64 {
        // Walking 1 cm a frame at 30 Hz; from frame 15 the odometry has relocalised.
        let pose = Translation3::new(0.01 * k as f64, 0.0, 0.0) * start;
        let odometry = match k >= 15 {
            true => {
                Translation3::new(step_m, 0.0, 0.0)
                    * UnitQuaternion::from_euler_angles(0.0, 0.0, step_deg.to_radians())
                    * pose
            }
            false => pose,
        };
        let update = map.update(&corner(&pose), &Pose { stamp_ns: k * 33_333_333, transform: odometry }, &intr, None);
        if update.odometry_step {
            stepped_at.push(k);
        }
    }
    assert_eq!(stepped_at, vec![15], "one step, when it happened");
    assert_eq!(map.counters.odometry_steps, 1);
    assert!((map.drift.yaw.to_degrees() - step_deg).abs() < 0.02, "yaw {} deg", map.drift.yaw.to_degrees());
    let snap = map.snapshot();
    assert_eq!(snap.polygons.len(), 4, "nothing smeared into a second copy");
    let riser = snap.polygons.iter().find(|p| p.normal[0].abs() > 0.9).unwrap();
    assert!((riser.centroid[0] - 0.5).abs() < 2e-3, "{:?}", riser.centroid);
}

#[test]
fn drift_is_measured_on_matched_horizontals_and_taken_out() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let floor = rect(-1.0, -1.0, 1.0, 1.0);
    let tread = rect(1.0, -0.5, 1.28, 0.5);
    map.update(&[seen(&floor, 0.0, &pose), seen(&tread, 0.15, &pose)], &posed(&pose), &intr, None);
    // The odometry drifts up 1 mm a frame: everything seems to sink.
    for k in 1..=60 {
        let drifted = Translation3::new(0.0, 0.0, 0.001 * k as f64) * pose;
        let polys = [seen(&floor, 0.0, &pose), seen(&tread, 0.15, &pose)];
        map.update(&polys, &posed(&drifted), &intr, None);
    }
    assert!((map.drift.z - 0.060).abs() < 0.002, "drift estimate {} after 60 mm", map.drift.z);
    let snap = map.snapshot();
    assert_eq!(snap.polygons.len(), 2);
    let heights: Vec<f64> = snap.polygons.iter().map(|p| p.centroid[2]).collect();
    assert!(heights.iter().any(|h| h.abs() < 0.002) && heights.iter().any(|h| (h - 0.15).abs() < 0.002), "{heights:?}");
}

#[test]
fn labels_name_a_staircase() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let mut polys = vec![seen(&rect(-2.0, -1.0, 0.0, 1.0), 0.0, &pose)];
    for k in 1..=4 {
        let x = (k - 1) as f64 * 0.28;
        polys.push(seen(&rect(x, -0.5, x + 0.28, 0.5), 0.15 * k as f64, &pose));
    }
    polys.push(seen(&rect(1.12, -0.5, 2.12, 0.5), 0.75, &pose));
    // A riser: vertical, 15 cm tall, its top at tread 1.
    let riser = Polygon {
        id: 9,
        normal: [-1.0, 0.0, 0.0],
        offset: 0.0,
        area: 0.15,
        boundary: vec![[0.0, 0.5, 0.0], [0.0, -0.5, 0.0], [0.0, -0.5, 0.15], [0.0, 0.5, 0.15]],
        holes: vec![],
        boundary_kinds: vec![VertexKind::Inside; 4],
        hole_kinds: vec![],
        pixel_count: 500,
        inlier_ratio: 1.0,
        rms: 0.001,
        uncertainty: Default::default(),
        footing: polymap::extract::Footing::Steppable,
    };
    polys.push(riser.transformed(&pose.inverse()));
    map.update(&polys, &posed(&pose), &intr, None);
    let snap = map.snapshot();
    let label_at = |z: f64| {
        let p = snap.polygons.iter().find(|p| p.label.is_horizontal() && (p.centroid[2] - z).abs() < 0.01).unwrap();
        (p.label, p.step)
    };
    assert_eq!(label_at(0.0), (Label::Floor, Some(0)));
    assert_eq!(label_at(0.30), (Label::Tread, Some(2)));
    assert_eq!(label_at(0.75), (Label::Landing, Some(5)));
    let r = snap.polygons.iter().find(|p| p.normal[2].abs() < 0.1).unwrap();
    assert_eq!((r.label, r.step), (Label::Riser, Some(1)));
    let stair = snap.stair.as_ref().expect("a stair");
    assert_eq!(stair.steps, 5);
    assert!((stair.step_height - 0.15).abs() < 1e-6);
    assert!((stair.tread_depth.unwrap() - 0.28).abs() < 1e-6);
}

#[test]
fn bad_polygons_and_poses_are_refused_and_counted() {
    let (pose, intr) = camera();
    let mut map = PolygonMap::new(&MapConfig::default());
    let good = seen(&rect(0.0, 0.0, 1.0, 1.0), 0.0, &pose);
    let mut nan = good.clone();
    nan.boundary[1][0] = f64::NAN;
    let mut not_unit = good.clone();
    not_unit.normal = [0.0, 0.0, 2.0];
    let mut two = good.clone();
    two.boundary.truncate(2);
    let update = map.update(&[nan, not_unit, two, good.clone()], &posed(&pose), &intr, None);
    assert_eq!(update.rejected.len(), 3, "{:?}", update.rejected);
    let problems: Vec<&PolygonProblem> = update
        .rejected
        .iter()
        .map(|r| match r {
            Rejection::Polygon { problem, .. } => problem,
            other => panic!("a polygon's problem, not {other}"),
        })
        .collect();
    assert!(
        matches!(
            problems[..],
            [PolygonProblem::VertexOutOfReach, PolygonProblem::NormalNotUnit(_), PolygonProblem::TooFewVertices(2)]
        ),
        "{problems:?}"
    );
    assert!(update.rejected[0].to_string().contains("not finite"), "{}", update.rejected[0]);
    assert!(update.rejected[1].to_string().contains("unit"), "{}", update.rejected[1]);
    assert!(update.rejected[2].to_string().contains("3"), "{}", update.rejected[2]);
    assert_eq!(map.len(), 1);
    let mut bad_pose = pose;
    bad_pose.translation.x = f64::INFINITY;
    let before = map.snapshot();
    let update = map.update(&[good], &posed(&bad_pose), &intr, None);
    assert!(update.rejected.iter().any(|r| matches!(r, Rejection::Pose { .. }) && r.to_string().contains("pose")));
    assert_eq!(map.snapshot(), before, "a bad pose leaves the map as it was");
    assert_eq!(map.counters.rejected, 4);
}

#[test]
fn snapshots_round_trip_and_corrupt_files_are_moved_aside() {
    let (pose, intr) = camera();
    let cfg = MapConfig::default();
    let mut map = PolygonMap::new(&cfg);
    for _ in 0..2 {
        map.update(&[seen(&rect(0.0, 0.0, 1.0, 0.5), 0.0, &pose)], &posed(&pose), &intr, None);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("map.json");
    let snap = map.snapshot();
    persist::save(&snap, &path).unwrap();
    let loaded =
        persist::load(&path, |s| PolygonMap::from_snapshot(&cfg, s).map(|_| s.clone()).map_err(|e| e.to_string()))
            .unwrap();
    assert_eq!(loaded, snap);
    let mut reloaded = PolygonMap::from_snapshot(&cfg, &loaded).unwrap();
    let again = reloaded.snapshot();
    assert_eq!(again.polygons.len(), 1);
    assert!((again.polygons[0].area - snap.polygons[0].area).abs() < 1e-9);
    assert_eq!(again.polygons[0].observations, 2);

    std::fs::write(&path, b"{\"frame\": \"world\", \"drift_z\": ").unwrap();
    let err = persist::load(&path, |s| Ok(s.clone())).unwrap_err().to_string();
    assert!(err.contains("corrupt") && err.contains("map.json"), "{err}");
    assert!(!path.exists(), "the corrupt file was moved, not left to be overwritten");
    let aside: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(aside.iter().any(|n| n.to_string_lossy().starts_with("map.json.corrupt-")), "{aside:?}");

    let mut bad: MapSnapshot = snap.clone();
    bad.polygons[0].normal = [0.0, 0.0, 0.0];
    let refused = PolygonMap::from_snapshot(&cfg, &bad).err().expect("a zero normal is refused");
    assert!(
        matches!(
            refused,
            SnapshotProblem::Polygon(Rejection::Polygon { problem: PolygonProblem::NormalNotUnit(_), .. })
        ),
        "{refused}"
    );
    assert!(refused.to_string().contains("normal"), "{refused}");
}

fn ring_area(r: &[[f64; 3]]) -> f64 {
    let mut a = 0.0;
    for i in 0..r.len() {
        let (p, q) = (r[i], r[(i + 1) % r.len()]);
        a += p[0] * q[1] - q[0] * p[1];
    }
    (a / 2.0).abs()
}

/// A random simple polygon: star-shaped around the origin (sorted angles, radii 0.3..1).
fn star(n: usize) -> impl Strategy<Value = Shape<f64>> {
    (prop::collection::vec(0.0..1.0f64, n), prop::collection::vec(0.3..1.0f64, n)).prop_map(|(gaps, radii)| {
        let total: f64 = gaps.iter().map(|g| g + 0.2).sum();
        let mut angle = 0.0;
        let pts: Vec<Coord<f64>> = gaps
            .iter()
            .zip(&radii)
            .map(|(g, r)| {
                angle += (g + 0.2) / total * std::f64::consts::TAU;
                Coord { x: r * angle.cos(), y: r * angle.sin() }
            })
            .collect();
        Shape::new(LineString::from(pts), vec![])
    })
}

fn with_hole(s: Shape<f64>, hole: bool) -> Shape<f64> {
    if !hole {
        return s;
    }
    // Every star's radii are at least 0.3: a square of half-side 0.1 round the origin fits.
    let h = LineString::from(vec![(-0.1, -0.1), (-0.1, 0.1), (0.1, 0.1), (0.1, -0.1)]);
    Shape::new(s.exterior().clone(), vec![h])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn convex_pieces_are_convex_and_tile_the_polygon(s in star(12), hole in any::<bool>()) {
        let s = with_hole(s, hole);
        let pieces = convex_pieces(&s);
        prop_assert!(!pieces.is_empty());
        let area = s.unsigned_area();
        let mut sum = 0.0;
        let mut union = geo::MultiPolygon::<f64>(vec![]);
        for p in &pieces {
            let n = p.len();
            prop_assert!(n >= 3);
            for i in 0..n {
                let (a, b, c) = (p[i], p[(i + 1) % n], p[(i + 2) % n]);
                let cross = (b.x - a.x) * (c.y - b.y) - (b.y - a.y) * (c.x - b.x);
                prop_assert!(cross >= -1e-12, "a right turn in piece {p:?}");
            }
            let shape = Shape::new(LineString::from(p.clone()), vec![]);
            sum += shape.unsigned_area();
            union = union.union(&shape);
        }
        prop_assert!((sum - area).abs() <= 1e-9 * area, "pieces {sum} vs polygon {area}");
        let diff = union.xor(&geo::MultiPolygon(vec![s.clone()])).unsigned_area();
        // Boolean operations snap to a fixed grid: their own round-off is about 1e-9 m^2.
        prop_assert!(diff <= 1e-7 * area, "pieces and polygon differ by {diff}");
    }

    #[test]
    fn the_convex_region_around_a_point_is_convex_inside_the_shape_and_holds_the_point(
        s in star(12), hole in any::<bool>(), qx in -1.0..1.0f64, qy in -1.0..1.0f64,
    ) {
        use geo::{Contains, Distance, Euclidean};
        let s = with_hole(s, hole);
        let q = Coord { x: qx, y: qy };
        let region = polymap::map::convex::convex_region_around(&s, q).expect("a star has area");
        let n = region.len();
        for i in 0..n {
            let (a, b, c) = (region[i], region[(i + 1) % n], region[(i + 2) % n]);
            let cross = (b.x - a.x) * (c.y - b.y) - (b.y - a.y) * (c.x - b.x);
            prop_assert!(cross >= -1e-12, "a right turn in {region:?}");
        }
        let shape = Shape::new(LineString::from(region), vec![]);
        prop_assert!(shape.unsigned_area() > 0.0);
        let out = geo::MultiPolygon(vec![shape.clone()]).difference(&geo::MultiPolygon(vec![s.clone()])).unsigned_area();
        prop_assert!(out <= 1e-7, "{out} m^2 outside the shape");
        // A point well inside the shape lies in its region.
        let inside = s.contains(&geo::Point(q)) && Euclidean.distance(&geo::Point(q), s.exterior()) > 1e-6
            && s.interiors().iter().all(|h| Euclidean.distance(&geo::Point(q), h) > 1e-6);
        if inside {
            prop_assert!(Euclidean.distance(&geo::Point(q), &shape) < 1e-9, "the region misses the point");
        }
    }

    #[test]
    fn union_of_overlapping_polygons_contains_both(a in star(9), b in star(9), dx in -0.3..0.3f64, dy in -0.3..0.3f64) {
        use geo::Translate;
        let b = b.translate(dx, dy);
        let u = polymap::map::geometry::union(&a, &b).expect("they overlap round the origin");
        let u = geo::MultiPolygon(vec![u]);
        for s in [&a, &b] {
            let outside = geo::MultiPolygon(vec![s.clone()]).difference(&u).unsigned_area();
            // Boolean operations snap to a fixed grid: their own round-off is about 1e-9 m^2.
            prop_assert!(outside <= 1e-7 * s.unsigned_area(), "{outside} m^2 of a part is outside the union");
        }
        let expected = a.unsigned_area() + b.unsigned_area() - a.intersection(&b).unsigned_area();
        prop_assert!((u.unsigned_area() - expected).abs() <= 1e-7 * expected);
    }
}

#[test]
fn simplified_shapes_stay_within_the_vertex_budget_however_many_holes_they_have() {
    use polymap::map::geometry::{largest, simplify_to, vertex_count};
    // A 1 m square with 40 holes of 4 x 4 cm (each stays a ring of at least 3 vertices
    // however far it is simplified), 8 slivers of 1 mm x 2 cm and 2 of 2 mm x 0.9 m.
    let square =
        |x: f64, y: f64, w: f64, h: f64| LineString::from(vec![(x, y), (x + w, y), (x + w, y + h), (x, y + h), (x, y)]);
    let mut holes: Vec<LineString<f64>> =
        (0..40).map(|k| square(0.05 + 0.1 * (k % 8) as f64, 0.05 + 0.15 * (k / 8) as f64, 0.04, 0.04)).collect();
    holes.extend((0..8).map(|k| square(0.05 + 0.1 * k as f64, 0.85, 0.001, 0.02)));
    holes.extend((0..2).map(|k| square(0.05, 0.9 + 0.03 * k as f64, 0.9, 0.002)));
    let s = Shape::new(square(0.0, 0.0, 1.0, 1.0), holes);
    let simple = simplify_to(&s, 64);
    assert!(vertex_count(&simple) <= 64, "{} vertices", vertex_count(&simple));
    assert!(!simple.interiors().is_empty(), "the largest holes that fit stay");
    // Boolean operations' results keep real holes and drop slivers.
    let kept = largest(geo::MultiPolygon(vec![s])).unwrap();
    assert_eq!(kept.interiors().len(), 40, "4 x 4 cm holes are gaps; 1 mm x 2 cm and 2 mm x 0.9 m ones slivers");
}

#[test]
fn a_view_pyramid_meets_a_plane_in_what_the_image_shows_of_it() {
    use polymap::map::geometry::{PlaneFrame, ViewPyramid};
    // 1 m over the floor looking straight down, a 201 x 101 image at f = 100 px: the image
    // spans 2 m across (world y) and 1 m along (world x).
    let pose = polymap::synth::path::camera_pose(Point3::new(0.0, 0.0, 1.0), 0.0, 90f64.to_radians(), 0.0);
    let intr = Intrinsics { width: 201, height: 101, fx: 100.0, fy: 100.0, cx: 100.0, cy: 50.0, depth_scale: 0.001 };
    let floor = PlaneFrame::new(Vector3::zeros(), Vector3::z());
    let seen = ViewPyramid::new(&pose, &intr, 0.0).on_plane(&floor).expect("the floor is in view");
    assert!((seen.unsigned_area() - 2.0).abs() < 1e-9, "area {}", seen.unsigned_area());
    let xs = seen.exterior().points().map(|p| p.x());
    let (x0, x1) = xs.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
    assert!((x0 + 0.5).abs() < 1e-9 && (x1 - 0.5).abs() < 1e-9, "x {x0}..{x1}");
    // A 10 px margin takes 0.1 m off each side.
    let inner = ViewPyramid::new(&pose, &intr, 10.0).on_plane(&floor).unwrap();
    assert!((inner.unsigned_area() - 1.8 * 0.8).abs() < 1e-9, "area {}", inner.unsigned_area());
    // A ceiling over the camera is behind it: not in view.
    let ceiling = PlaneFrame::new(Vector3::new(0.0, 0.0, 2.0), Vector3::z());
    assert!(ViewPyramid::new(&pose, &intr, 0.0).on_plane(&ceiling).is_none());
}

#[test]
fn clearing_reaches_the_corners_of_the_view_and_nothing_outside_it() {
    let (pose, _) = camera();
    let intr = Intrinsics::L515_320X240;
    // Where pixel (u, v)'s ray meets the floor.
    let floor_at = |u: f64, v: f64| {
        let ray = pose.rotation * intr.ray(u, v);
        let p = pose.translation.vector + ray * (-pose.translation.vector.z / ray.z);
        [p.x, p.y]
    };
    let tile = |[x, y]: [f64; 2], half: f64| seen(&rect(x - half, y - half, x + half, y + half), 0.0, &pose);
    let centre = tile(floor_at(160.0, 120.0), 0.2);
    let corner = tile(floor_at(6.0, 6.0), 0.03);
    let behind = tile([-10.0, 0.0], 0.2);
    let mut map = PolygonMap::new(&MapConfig::default());
    map.update(&[centre, corner, behind], &posed(&pose), &intr, None);
    assert_eq!(map.len(), 3);
    // The depth image sees 4 m further than the floor everywhere: through the floor tiles.
    let depth = Grid { width: 320, height: 240, data: vec![8.0f32; 320 * 240] };
    let mut removed = Vec::new();
    for _ in 0..MapConfig::default().clear_after_frames {
        removed.extend(map.update(&[], &posed(&pose), &intr, Some(&depth)).removed);
    }
    removed.sort_unstable();
    assert_eq!(removed, vec![1, 2], "the tiles in view, the one at the image's corner too, are cleared");
    assert_eq!(map.ids(), vec![3], "the one behind the camera is left alone");
    assert_eq!(map.counters.cleared, 2);
}
