//! The planar terrain of a mapped staircase, checked cell by cell as a planner would read it:
//! the bundled stairs replayed through the extractor (CPU twin) and the map, then
//! interface::terrain::planar_terrain around the stairs' middle.

use std::path::Path;

use geo::{Contains, Coord, Distance, Euclidean, Point, Polygon as Shape};
use polymap::config::{Backend, Config};
use polymap::interface::terrain::{LAYERS, planar_terrain};
use polymap::map::elevation::GridSpec;
use polymap::map::geometry::top_down;
use polymap::map::{Label, MapPolygon, PolygonMap};
use polymap::sequence::Sequence;

#[test]
fn the_terrain_grid_holds_each_surface_at_its_plane_height_and_nan_off_every_surface() {
    let seq = Sequence::open(Path::new(env!("CARGO_MANIFEST_DIR")).join("mock_frames/straight_320")).unwrap();
    let mut config = Config::default();
    config.pipeline.backend = Backend::Cpu;
    let mut map = PolygonMap::new(&config.map);
    polymap::replay::replay(&seq, &config, &mut map, |_, _, _| {}).unwrap();
    let snapshot = map.snapshot();
    let treads: Vec<&MapPolygon> = snapshot.polygons.iter().filter(|p| p.label == Label::Tread).collect();
    assert!(treads.len() >= 5, "{} treads mapped", treads.len());
    let n = treads.len() as f64;
    let robot =
        [treads.iter().map(|p| p.centroid[0]).sum::<f64>() / n, treads.iter().map(|p| p.centroid[1]).sum::<f64>() / n];

    let cfg = &config.planar_terrain;
    let terrain = planar_terrain(&snapshot, robot, cfg, 0, "map");
    let spec = GridSpec::around(robot, cfg.resolution_m, [cfg.length_x_m, cfg.length_y_m]);
    let grid = &terrain.gridmap;
    assert_eq!(grid.layers, LAYERS.map(String::from).to_vec());
    let (elevation, smooth, region) = (&grid.data[0].data, &grid.data[1].data, &grid.data[2].data);
    assert_eq!(elevation.len(), spec.rows * spec.cols);
    assert_eq!(
        elevation.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        smooth.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );

    // The surfaces a foot may stand on; which of them are regions, by map id.
    let min_up = cfg.max_tilt_deg.to_radians().cos();
    let standable: Vec<(&MapPolygon, Shape<f64>)> = snapshot
        .polygons
        .iter()
        .filter(|p| p.normal[2].abs() >= min_up)
        .map(|p| (p, top_down(&p.boundary, &p.holes)))
        .collect();
    let region_heights: Vec<f64> = terrain.planar_regions.iter().map(|r| r.plane_parameters.position.z).collect();

    let (mut on, mut off, mut near_edge) = (0usize, 0usize, 0usize);
    let mut cells_per_tread = vec![0usize; treads.len()];
    for row in 0..spec.rows {
        for col in 0..spec.cols {
            let [x, y] = spec.cell_centre(row, col);
            let at = Point::new(x, y);
            // A centre within a millimetre of an outline could fall either way.
            if standable.iter().any(|(_, s)| {
                std::iter::once(s.exterior()).chain(s.interiors()).any(|r| Euclidean.distance(&at, r) < 1e-3)
            }) {
                near_edge += 1;
                continue;
            }
            let k = spec.index(row, col);
            let highest = standable
                .iter()
                .filter(|(_, s)| s.contains(&Coord { x, y }))
                .map(|(p, _)| (p.height_at(x, y), *p))
                .max_by(|a, b| a.0.total_cmp(&b.0));
            match highest {
                None => {
                    assert!(elevation[k].is_nan(), "cell ({row}, {col}) at ({x:.3}, {y:.3}) is off every surface");
                    assert!(region[k].is_nan());
                    off += 1;
                }
                Some((z, p)) => {
                    // The height at the cell's centre, to f32's precision.
                    assert!((elevation[k] as f64 - z).abs() < 1e-5, "cell ({row}, {col}): {} vs {z}", elevation[k]);
                    if let Some(t) = treads.iter().position(|t| t.id == p.id) {
                        cells_per_tread[t] += 1;
                        // The region it names is that surface: the same plane.
                        let r = region[k];
                        assert!(!r.is_nan(), "tread {} cell without a region", p.id);
                        let plane = region_heights[r as usize];
                        assert!(
                            (plane - p.centroid[2]).abs() < 0.02,
                            "region {r} at {plane} for tread {} at {}",
                            p.id,
                            p.centroid[2]
                        );
                    }
                    on += 1;
                }
            }
        }
    }
    eprintln!(
        "{on} cells on a surface, {off} off every surface (NaN), {near_edge} within 1 mm of an outline; \
         cells per tread {cells_per_tread:?}"
    );
    assert!(off > 1000 && on > 1000);
    // Every tread is in the grid (4 cm cells on treads 28 cm deep and 1 m wide).
    assert!(cells_per_tread.iter().all(|&c| c >= 50), "{cells_per_tread:?}");

    // And against the truth: the grid's height at the middle of each true tread.
    let truth = seq.truth.as_ref().unwrap();
    let mut checked = 0;
    for t in truth.polygons.iter().filter(|t| t.label == "tread") {
        let n = t.boundary.len() as f64;
        let (x, y) =
            (t.boundary.iter().map(|v| v[0]).sum::<f64>() / n, t.boundary.iter().map(|v| v[1]).sum::<f64>() / n);
        let half = spec.resolution / 2.0;
        let top = spec.cell_centre(0, 0);
        let (row, col) =
            (((top[0] - x + half) / spec.resolution) as usize, ((top[1] - y + half) / spec.resolution) as usize);
        if row >= spec.rows || col >= spec.cols {
            continue;
        }
        let z = elevation[spec.index(row, col)];
        if z.is_nan() {
            // A tread the camera never saw (the top one, in this walk) has no cells.
            assert!(
                !treads.iter().any(|p| (p.centroid[2] - t.height).abs() < 0.02),
                "tread at {} mapped but not in the grid",
                t.height
            );
            continue;
        }
        assert!((z as f64 - t.height).abs() < 0.01, "true tread at {:.3} m, grid {z:.3} m", t.height);
        checked += 1;
    }
    assert!(checked >= 5, "{checked} true treads found in the grid");

    // Every tread of the replayed walk is steppable; one marked otherwise leaves the
    // regions (a foot may not go there) but not the grid (the terrain's shape stays).
    assert!(treads.iter().all(|p| p.footing.is_steppable()), "every mapped tread is steppable");
    let mut doubtful = snapshot.clone();
    let unsure = doubtful.polygons.iter_mut().find(|p| p.label == Label::Tread && p.id == treads[2].id).unwrap();
    unsure.footing = polymap::extract::Footing::TiltUnknown;
    let without = planar_terrain(&doubtful, robot, cfg, 0, "map");
    assert_eq!(without.planar_regions.len(), terrain.planar_regions.len() - 1);
    let gone = treads[2].centroid[2];
    let at_its_height = |t: &polymap::ros2::msg::PlanarTerrain| {
        t.planar_regions.iter().filter(|r| (r.plane_parameters.position.z - gone).abs() < 0.02).count()
    };
    assert_eq!(at_its_height(&without), at_its_height(&terrain) - 1, "its region is the one gone");
    let bits =
        |t: &polymap::ros2::msg::PlanarTerrain| t.gridmap.data[0].data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&without), bits(&terrain), "the elevation keeps it");
}
