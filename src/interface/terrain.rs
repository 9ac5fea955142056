//! The map as convex_plane_decomposition_msgs/PlanarTerrain, the way legged planners that
//! read it expect it (OCS2's segmented-planes terrain model, legged_perceptive): every
//! surface a foot may stand on is a PlanarRegion in its plane's frame (z along the upward
//! normal, x and y as convex_plane_decomposition chooses them), with its outline, holes and
//! insets in that frame's x and y (outlines counter-clockwise, holes clockwise, first point
//! not repeated), and a grid_map_msgs/GridMap in the same frame with `elevation` and
//! `smooth_planar` layers and a `region` layer (the index in `planar_regions` of the region a
//! cell lies in).

use geo::Coord;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::convert::header;
use crate::config::PlanarTerrainConfig;
use crate::map::elevation::{self, GridSpec, Surface};
use crate::map::geometry::signed_area;
use crate::map::{MapPolygon, MapSnapshot, Region};
use crate::ros2::msg::{
    BoundingBox2d, Float32MultiArray, GridMap, GridMapInfo, MultiArrayDimension, MultiArrayLayout, PlanarRegion,
    PlanarTerrain, Point, Point2d, Polygon2d, PolygonWithHoles2d, Pose, Quaternion,
};
use crate::types::StampNs;

/// The grid map's layers, in order. `smooth_planar` is convex_plane_decomposition's name for
/// the elevation projected onto the planes; polymap's elevation already is, so both carry the
/// same heights (OCS2 builds its signed distance field from `elevation` and extrapolates
/// references on `smooth_planar`).
pub const LAYERS: [&str; 3] = ["elevation", "smooth_planar", "region"];

/// The terrain around `robot` (x, y in the map frame), in `frame_id`.
pub fn planar_terrain(
    s: &MapSnapshot,
    robot: [f64; 2],
    cfg: &PlanarTerrainConfig,
    stamp_ns: StampNs,
    frame_id: &str,
) -> PlanarTerrain {
    let spec = GridSpec::around(robot, cfg.resolution_m, [cfg.length_x_m, cfg.length_y_m]);
    let min_up = cfg.max_tilt_deg.to_radians().cos();
    let standable: Vec<&MapPolygon> = s.polygons.iter().filter(|p| p.normal[2].abs() >= min_up).collect();
    // Regions: the standable surfaces a foot fits on (planners need at least one inset) and
    // may trust (steppable) near the grid, so the message stays the grid's size however
    // large the map grows. The elevation keeps every standable surface: the terrain's shape.
    let near = |p: &MapPolygon| overlaps(&spec, &p.boundary);
    let regions: Vec<&MapPolygon> =
        (standable.iter().copied()).filter(|p| p.footing.is_steppable() && !p.insets.is_empty() && near(p)).collect();
    let surfaces: Vec<Surface> = standable
        .iter()
        .map(|&p| Surface { polygon: p, region: regions.iter().position(|r| r.id == p.id).map(|i| i as u32) })
        .collect();
    let raster = elevation::rasterise(spec, &surfaces);
    let layer = |data: Vec<f32>| Float32MultiArray {
        // grid_map's Eigen matrices are column-major: columns outermost.
        layout: MultiArrayLayout {
            dim: vec![
                MultiArrayDimension {
                    label: "column_index".into(),
                    size: spec.cols as u32,
                    stride: (spec.rows * spec.cols) as u32,
                },
                MultiArrayDimension { label: "row_index".into(), size: spec.rows as u32, stride: spec.rows as u32 },
            ],
            data_offset: 0,
        },
        data,
    };
    let [length_x, length_y] = spec.length();
    PlanarTerrain {
        planar_regions: regions.iter().map(|p| planar_region(p)).collect(),
        gridmap: GridMap {
            header: header(stamp_ns, frame_id),
            info: GridMapInfo {
                resolution: spec.resolution,
                length_x,
                length_y,
                pose: Pose {
                    position: Point { x: spec.centre[0], y: spec.centre[1], z: 0.0 },
                    orientation: Quaternion::default(),
                },
            },
            layers: LAYERS.iter().map(|l| l.to_string()).collect(),
            basic_layers: Vec::new(),
            data: vec![layer(raster.elevation.clone()), layer(raster.elevation), layer(raster.region)],
            outer_start_index: 0,
            inner_start_index: 0,
        },
    }
}

/// Whether an outline's x-y box meets the grid's.
fn overlaps(spec: &GridSpec, ring: &[[f64; 3]]) -> bool {
    let [lx, ly] = spec.length();
    let [cx, cy] = spec.centre;
    let (lo, hi) = ring.iter().fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), p| {
        ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
    });
    lo[0] <= cx + lx / 2.0 && hi[0] >= cx - lx / 2.0 && lo[1] <= cy + ly / 2.0 && hi[1] >= cy - ly / 2.0
}

/// The plane's frame as convex_plane_decomposition makes it: z the upward normal,
/// y = normalize(z x world x) (or, for a normal near world x, z x (world y x z)), x = y x z;
/// its origin the polygon's centroid on the plane.
pub fn plane_frame(p: &MapPolygon) -> (Vector3<f64>, Matrix3<f64>) {
    let mut z = Vector3::from(p.normal).normalize();
    let mut offset = p.offset;
    if z.z < 0.0 {
        z = -z;
        offset = -offset;
    }
    let y = z.cross(&Vector3::x());
    let y = if y.norm_squared() > 1e-3 { y.normalize() } else { z.cross(&Vector3::y().cross(&z)).normalize() };
    let x = y.cross(&z);
    let c = Vector3::from(p.centroid);
    let origin = c - z * (z.dot(&c) + offset);
    (origin, Matrix3::from_columns(&[x, y, z]))
}

fn planar_region(p: &MapPolygon) -> PlanarRegion {
    let (origin, axes) = plane_frame(p);
    let to_plane = |v: &[f64; 3]| {
        let d = Vector3::from(*v) - origin;
        Coord { x: d.dot(&axes.column(0)), y: d.dot(&axes.column(1)) }
    };
    // Outlines counter-clockwise, holes clockwise, in the plane's x-y.
    let polygon2d = |ring: &[[f64; 3]], ccw: bool| {
        let mut pts: Vec<Coord<f64>> = ring.iter().map(to_plane).collect();
        if (signed_area(&pts) > 0.0) != ccw {
            pts.reverse();
        }
        Polygon2d { points: pts.iter().map(|c| Point2d { x: c.x as f32, y: c.y as f32 }).collect() }
    };
    let with_holes = |r: &Region| PolygonWithHoles2d {
        outer_boundary: polygon2d(&r.boundary, true),
        holes: r.holes.iter().map(|h| polygon2d(h, false)).collect(),
    };
    let boundary = with_holes(&Region { boundary: p.boundary.clone(), holes: p.holes.clone() });
    let bbox2d = boundary.outer_boundary.points.iter().fold(
        BoundingBox2d {
            min_x: f32::INFINITY,
            min_y: f32::INFINITY,
            max_x: f32::NEG_INFINITY,
            max_y: f32::NEG_INFINITY,
        },
        |b, q| BoundingBox2d {
            min_x: b.min_x.min(q.x),
            min_y: b.min_y.min(q.y),
            max_x: b.max_x.max(q.x),
            max_y: b.max_y.max(q.y),
        },
    );
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    PlanarRegion {
        plane_parameters: Pose {
            position: Point { x: origin.x, y: origin.y, z: origin.z },
            orientation: Quaternion { x: q.i, y: q.j, z: q.k, w: q.w },
        },
        bbox2d,
        boundary,
        insets: p.insets.iter().map(with_holes).collect(),
    }
}
