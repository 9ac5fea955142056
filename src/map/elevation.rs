//! The map as a height grid around a point, in grid_map's layout (what legged planners read
//! as the elevation layer of a GridMap): rows along x, columns along y, cell (0, 0) at the
//! grid's +x/+y corner, values column-major. A cell takes the height of the highest surface
//! whose outline (holes excluded) holds its centre, seen from above; cells off every surface
//! are NaN.

use super::MapPolygon;

/// Where the grid lies: its centre, cell size and extent (a whole number of cells).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridSpec {
    /// m per cell.
    pub resolution: f64,
    pub rows: usize,
    pub cols: usize,
    /// The grid's centre, x and y, m: a multiple of the resolution, so cells stay put as
    /// the centre follows the robot.
    pub centre: [f64; 2],
}

impl GridSpec {
    /// A grid of about `length` (x, y; m) centred near `point`.
    pub fn around(point: [f64; 2], resolution: f64, length: [f64; 2]) -> GridSpec {
        let cells = |l: f64| ((l / resolution).round() as usize).max(1);
        let snap = |v: f64| (v / resolution).round() * resolution;
        GridSpec {
            resolution,
            rows: cells(length[0]),
            cols: cells(length[1]),
            centre: [snap(point[0]), snap(point[1])],
        }
    }

    /// Extent along x and y, m.
    pub fn length(&self) -> [f64; 2] {
        [self.rows as f64 * self.resolution, self.cols as f64 * self.resolution]
    }

    /// Centre of the cell's first row / column (the +x / +y end), m.
    fn top(&self) -> [f64; 2] {
        let [lx, ly] = self.length();
        [self.centre[0] + lx / 2.0 - self.resolution / 2.0, self.centre[1] + ly / 2.0 - self.resolution / 2.0]
    }

    /// The centre of cell (row, col), m.
    pub fn cell_centre(&self, row: usize, col: usize) -> [f64; 2] {
        let top = self.top();
        [top[0] - row as f64 * self.resolution, top[1] - col as f64 * self.resolution]
    }

    /// Where cell (row, col) is in a layer's data (column-major).
    pub fn index(&self, row: usize, col: usize) -> usize {
        col * self.rows + row
    }
}

/// A surface to draw: a map polygon, and the number its cells get in the region layer.
pub struct Surface<'a> {
    pub polygon: &'a MapPolygon,
    pub region: Option<u32>,
}

/// The layers, each `rows * cols` long, column-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Raster {
    pub spec: GridSpec,
    /// The surface's height at the cell's centre, m; NaN off every surface.
    pub elevation: Vec<f32>,
    /// The region number of that surface; NaN where it has none.
    pub region: Vec<f32>,
}

/// The surfaces drawn on the grid. Surfaces must not be vertical (their normal's z is
/// away from 0); the highest wins where they overlap seen from above.
pub fn rasterise(spec: GridSpec, surfaces: &[Surface]) -> Raster {
    let cells = spec.rows * spec.cols;
    let mut raster = Raster { spec, elevation: vec![f32::NAN; cells], region: vec![f32::NAN; cells] };
    let top = spec.top();
    let res = spec.resolution;
    let mut crossings: Vec<f64> = Vec::new();
    for s in surfaces {
        let p = s.polygon;
        if p.normal[2].abs() < 1e-6 {
            continue;
        }
        let rings: Vec<&Vec<[f64; 3]>> = std::iter::once(&p.boundary).chain(&p.holes).collect();
        let (lo, hi) =
            p.boundary.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v[0]), hi.max(v[0])));
        // Rows whose centre line x = const meets the outline's x extent.
        let first_row = ((top[0] - hi) / res).ceil().max(0.0) as usize;
        let last_row = ((top[0] - lo) / res).floor().min(spec.rows as f64 - 1.0);
        if last_row < 0.0 {
            continue;
        }
        for row in first_row..=last_row as usize {
            let x = top[0] - row as f64 * res;
            // Where the line x = const crosses the rings: inside between pairs (even-odd,
            // each edge half-open so a vertex on the line counts once).
            crossings.clear();
            for ring in &rings {
                for i in 0..ring.len() {
                    let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                    if (a[0] <= x) != (b[0] <= x) {
                        crossings.push(a[1] + (x - a[0]) * (b[1] - a[1]) / (b[0] - a[0]));
                    }
                }
            }
            crossings.sort_by(f64::total_cmp);
            for span in crossings.chunks_exact(2) {
                let first_col = ((top[1] - span[1]) / res).ceil().max(0.0) as usize;
                let last_col = ((top[1] - span[0]) / res).floor().min(spec.cols as f64 - 1.0);
                if last_col < 0.0 {
                    continue;
                }
                for col in first_col..=last_col as usize {
                    let y = top[1] - col as f64 * res;
                    let z = p.height_at(x, y) as f32;
                    let k = spec.index(row, col);
                    if raster.elevation[k].is_nan() || raster.elevation[k] < z {
                        raster.elevation[k] = z;
                        raster.region[k] = s.region.map_or(f32::NAN, |r| r as f32);
                    }
                }
            }
        }
    }
    raster
}
