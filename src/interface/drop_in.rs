//! `/polygon_new_markers`, the paper authors' ROS 1 topic, as the robot's own consumers read
//! it (README "ROS 1"): the vendor's stair planner walks the markers in
//! message order without sorting, takes a marker's first four points as a tread's corners,
//! and reads them as `odom` coordinates with z = 0 at the soles. So each frame's steppable
//! level polygons go out as four corners and the closing point, bottom-up (nearest first
//! within a level), the floor left out, in the robot's odometry frame.

use crate::config::DropInConfig;
use crate::extract::Polygon;
use crate::map::Label;
use crate::ros2::msg::{ColorRgba, Duration, MarkerArray, Point};
use crate::types::StampNs;

/// Treads whose heights differ by less than this are one level, m (a riser is 8 cm at least
/// for the planner).
const SAME_LEVEL_M: f64 = 0.04;

/// A frame's polygons (map frame, each with its label in the map, None if it went nowhere)
/// as the vendor's planner reads them: one closed blue LINE_STRIP per steppable level
/// polygon, its four corners (the minimum-area rectangle around its outline) and the first
/// again, bottom-up and nearest `robot` first within a level; ns `polygons_new`, id the
/// marker's place, 0.5 s lifetime, 5 cm wide, as the authors' node sends them.
pub fn polygon_new_markers(
    stamp_ns: StampNs,
    polygons: &[Polygon],
    labels: &[Option<Label>],
    robot: [f64; 3],
    cfg: &DropInConfig,
) -> MarkerArray {
    let min_normal_z = cfg.max_tilt_deg.to_radians().cos();
    let mut treads: Vec<(f64, f64, Vec<Point>)> = (polygons.iter().zip(labels))
        .filter(|(p, label)| {
            p.footing.is_steppable() && p.normal[2] >= min_normal_z && (cfg.floor || **label != Some(Label::Floor))
        })
        .filter_map(|(p, _)| {
            let corners: Vec<Point> = rectangle(p)?.into_iter().map(|c| cfg.to_frame(c).into()).collect();
            let height = corners.iter().map(|c| c.z).sum::<f64>() / 4.0;
            let centre = p.centroid();
            let distance = (centre[0] - robot[0]).hypot(centre[1] - robot[1]);
            Some((height, distance, corners))
        })
        .collect();
    treads.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Levels from the bottom: each starts at its lowest tread; nearest first within one.
    let mut start = 0;
    while start < treads.len() {
        let end = start + treads[start..].iter().take_while(|t| t.0 - treads[start].0 < SAME_LEVEL_M).count();
        treads[start..end].sort_by(|a, b| a.1.total_cmp(&b.1));
        start = end;
    }
    let header = super::convert::header(stamp_ns, &cfg.frame);
    let markers = (treads.into_iter().enumerate())
        .map(|(i, (_, _, mut points))| {
            let mut m = super::convert::marker(&header, i as u64, super::convert::MARKER_ADD);
            m.ns = "polygons_new".into();
            m.lifetime = Duration { sec: 0, nanosec: 500_000_000 };
            m.scale.x = 0.05;
            m.color = ColorRgba { r: 0.0, g: 0.0, b: 1.0, a: 1.0 };
            m.pose.orientation.w = 1.0;
            points.push(points[0]);
            m.points = points;
            m
        })
        .collect();
    MarkerArray { markers }
}

/// The four corners of the smallest rectangle around a level polygon's outline (in x-y),
/// each on the polygon's plane; None for an outline with no area.
fn rectangle(p: &Polygon) -> Option<[[f64; 3]; 4]> {
    use geo::MinimumRotatedRect;
    let outline: geo::MultiPoint<f64> = p.boundary.iter().map(|v| geo::Point::new(v[0], v[1])).collect();
    let rect = outline.minimum_rotated_rect()?;
    let ring = &rect.exterior().0;
    let (n, offset) = (p.normal, p.offset);
    let on_plane = |c: &geo::Coord<f64>| [c.x, c.y, -(n[0] * c.x + n[1] * c.y + offset) / n[2]];
    let corners: [[f64; 3]; 4] =
        [on_plane(ring.first()?), on_plane(ring.get(1)?), on_plane(ring.get(2)?), on_plane(ring.get(3)?)];
    let [a, b, c] = [corners[0], corners[1], corners[2]];
    let area = ((b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])).abs();
    (area > 0.0 && corners.iter().flatten().all(|v| v.is_finite())).then_some(corners)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extract::Footing;

    /// A level polygon at height z: its outline ragged, traced from mid-edge.
    fn tread(id: u32, x0: f64, z: f64, footing: Footing) -> Polygon {
        let corners = [[x0, -0.3], [x0 + 0.28, -0.3], [x0 + 0.28, 0.3], [x0, 0.3]];
        let mut boundary = Vec::new();
        for k in 0..4 {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            for s in 0..10 {
                let t = s as f64 / 10.0;
                let wobble = if s == 0 { 0.0 } else { 0.004 * ((s * 7 + k) as f64).sin().abs() };
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len = dx.hypot(dy);
                // Pulled inwards (to the left of a counter-clockwise edge) by the wobble.
                boundary.push([a[0] + t * dx - wobble * dy / len, a[1] + t * dy + wobble * dx / len, z]);
            }
        }
        boundary.rotate_left(5);
        Polygon {
            id,
            normal: [0.0, 0.0, 1.0],
            offset: -z,
            area: 0.168,
            boundary_kinds: vec![Default::default(); boundary.len()],
            boundary,
            holes: vec![],
            hole_kinds: vec![],
            pixel_count: 900,
            inlier_ratio: 1.0,
            rms: 0.001,
            uncertainty: Default::default(),
            footing,
        }
    }

    fn riser(id: u32, x: f64, z: f64) -> Polygon {
        let boundary = vec![[x, -0.3, z], [x, 0.3, z], [x, 0.3, z + 0.15], [x, -0.3, z + 0.15]];
        Polygon { normal: [-1.0, 0.0, 0.0], offset: x, boundary, ..tread(id, 0.0, 0.0, Footing::Steppable) }
    }

    #[test]
    fn level_treads_go_bottom_up_as_four_corners_in_the_robots_frame() {
        let s = Footing::Steppable;
        // As a frame lists them: highest first, a riser, the floor, one not steppable.
        let polygons = [
            tread(0, 0.84, 0.45, s),
            riser(1, 0.56, 0.15),
            tread(2, 0.56, 0.30, s),
            tread(3, -1.0, 0.0, s),
            tread(4, 0.28, 0.15, s),
            tread(5, 1.2, 0.60, Footing::TiltUnknown),
        ];
        let labels = [
            Some(Label::Tread),
            Some(Label::Riser),
            Some(Label::Tread),
            Some(Label::Floor),
            Some(Label::Tread),
            Some(Label::Tread),
        ];
        let cfg = DropInConfig { map_origin_xyz: [0.1, 0.0, 0.9], ..DropInConfig::default() };
        let markers = polygon_new_markers(7, &polygons, &labels, [0.0; 3], &cfg).markers;
        let heights: Vec<f64> = markers.iter().map(|m| m.points[..4].iter().map(|p| p.z).sum::<f64>() / 4.0).collect();
        assert_eq!(markers.len(), 3, "three treads, no riser, floor or uncertain tread: {heights:?}");
        for (m, (z, x0)) in markers.iter().zip([(1.05, 0.28), (1.2, 0.56), (1.35, 0.84)]) {
            assert_eq!((m.header.frame_id.as_str(), m.ns.as_str(), m.points.len()), ("odom", "polygons_new", 5));
            assert_eq!(m.points[0], m.points[4], "closed");
            assert!(m.points.iter().all(|p| (p.z - z).abs() < 1e-9), "height {z}: {:?}", m.points);
            // The rectangle around the ragged outline is the tread's own, moved by the origin.
            let mut xs: Vec<f64> = m.points[..4].iter().map(|p| p.x).collect();
            xs.sort_by(f64::total_cmp);
            assert!((xs[0] - (x0 + 0.1)).abs() < 1e-9 && (xs[3] - (x0 + 0.38)).abs() < 1e-9, "{xs:?}");
        }
        assert_eq!(markers.iter().map(|m| m.id).collect::<Vec<_>>(), [0, 1, 2]);
        // With the floor: first, at z = 0.9 here (the map's origin 0.9 m above the soles).
        let with_floor = DropInConfig { floor: true, ..cfg.clone() };
        let markers = polygon_new_markers(7, &polygons, &labels, [0.0; 3], &with_floor).markers;
        assert_eq!(markers.len(), 4);
        assert!((markers[0].points[0].z - 0.9).abs() < 1e-9);
    }

    #[test]
    fn within_a_level_the_nearest_goes_first_and_yaw_turns_the_map() {
        let s = Footing::Steppable;
        let polygons = [tread(0, 2.0, 0.15, s), tread(1, 0.5, 0.16, s), tread(2, 0.0, 0.30, s)];
        let labels = [Some(Label::Tread); 3];
        let cfg = DropInConfig { map_origin_yaw_deg: 90.0, ..DropInConfig::default() };
        let markers = polygon_new_markers(0, &polygons, &labels, [0.0; 3], &cfg).markers;
        let first_x: Vec<f64> =
            markers.iter().map(|m| m.points[..4].iter().map(|p| p.y).fold(f64::MAX, f64::min)).collect();
        // Map x is the frame's y after a quarter turn; the near tread of the lower level first.
        assert!(
            (first_x[0] - 0.5).abs() < 1e-9 && (first_x[1] - 2.0).abs() < 1e-9 && first_x[2].abs() < 1e-9,
            "{first_x:?}"
        );
    }
}
