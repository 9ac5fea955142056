//! Scenes made of planar polygons, and ray casting against them.
//!
//! Every visible face of every solid is one planar [`Surface`], so the truth
//! (truth.json) is exactly the geometry that is ray cast: the label image is the
//! index of the surface each ray hit.

use nalgebra::{Point3, Vector3};

use crate::sequence::{StairTruth, Truth, TruthPolygon};

/// Which synthetic world to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SceneKind {
    /// A straight staircase between two walls, floor before it, landing on top.
    Straight,
    /// A spiral staircase: wedge-shaped solid steps around a central post.
    Spiral,
    /// Open floor with a box on it and a short open-sided flight of steps.
    Box,
}

/// One planar face: its plane, in-plane axes and outline.
#[derive(Clone, Debug)]
pub struct Surface {
    pub label: &'static str,
    pub step: Option<u32>,
    /// Height of a horizontal face; of the top edge for any other, m.
    pub height: f64,
    pub boundary: Vec<Point3<f64>>,
    /// Unit normal (from the counter-clockwise order of `boundary`).
    pub normal: Vector3<f64>,
    origin: Point3<f64>,
    axis_u: Vector3<f64>,
    axis_v: Vector3<f64>,
    outline: Vec<[f64; 2]>,
}

impl Surface {
    /// A face from its boundary, counter-clockwise seen from the side it faces.
    pub fn new(label: &'static str, step: Option<u32>, height: f64, boundary: Vec<Point3<f64>>) -> Surface {
        // Newell's method: robust normal for any simple planar polygon.
        let mut n = Vector3::zeros();
        for (i, a) in boundary.iter().enumerate() {
            let b = boundary[(i + 1) % boundary.len()];
            n += Vector3::new((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
        }
        let normal = n.normalize();
        let origin = boundary[0];
        let axis_u = (boundary[1] - origin).normalize();
        let axis_v = normal.cross(&axis_u);
        let outline = boundary.iter().map(|p| [(p - origin).dot(&axis_u), (p - origin).dot(&axis_v)]).collect();
        Surface { label, step, height, boundary, normal, origin, axis_u, axis_v, outline }
    }

    /// Ray parameter t > 0 at which `origin + t * dir` hits this face, if it does.
    pub fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<f64> {
        let denom = self.normal.dot(dir);
        if denom.abs() < 1e-12 {
            return None;
        }
        let t = self.normal.dot(&(self.origin - origin)) / denom;
        if t <= 1e-9 {
            return None;
        }
        let rel = origin + dir * t - self.origin;
        point_in_polygon(rel.dot(&self.axis_u), rel.dot(&self.axis_v), &self.outline).then_some(t)
    }

    /// Plane offset d of n·p + d = 0.
    pub fn offset(&self) -> f64 {
        -self.normal.dot(&self.origin.coords)
    }
}

/// Even-odd rule; points on an edge may fall either way.
fn point_in_polygon(x: f64, y: f64, poly: &[[f64; 2]]) -> bool {
    let mut inside = false;
    let mut j = poly.len() - 1;
    for i in 0..poly.len() {
        let ([xi, yi], [xj, yj]) = (poly[i], poly[j]);
        if (yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// A scene: its faces (truth polygon i+1 = label i+1) and stair dimensions.
#[derive(Clone, Debug)]
pub struct Scene {
    pub kind: SceneKind,
    pub surfaces: Vec<Surface>,
    pub stair: Option<StairTruth>,
}

impl Scene {
    /// Nearest hit of a ray: (t, surface index).
    pub fn cast(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<(f64, usize)> {
        let mut best: Option<(f64, usize)> = None;
        for (i, s) in self.surfaces.iter().enumerate() {
            if let Some(t) = s.intersect(origin, dir)
                && best.is_none_or(|(bt, _)| t < bt)
            {
                best = Some((t, i));
            }
        }
        best
    }

    pub fn truth(&self) -> Truth {
        Truth {
            stair: self.stair.clone(),
            polygons: self
                .surfaces
                .iter()
                .map(|s| TruthPolygon {
                    label: s.label.to_string(),
                    step: s.step,
                    height: s.height,
                    boundary: s.boundary.iter().map(|p| [p.x, p.y, p.z]).collect(),
                })
                .collect(),
            pose_drift_per_frame: 0.0,
            pose_drift: None,
        }
    }

    /// The scene a sequence's truth.json describes (to render other sensors in it).
    pub fn from_truth(truth: &Truth) -> Scene {
        const LABELS: [&str; 8] = ["tread", "riser", "floor", "landing", "side", "post", "box_top", "box_side"];
        let surfaces = truth
            .polygons
            .iter()
            .map(|p| {
                let label = LABELS.into_iter().find(|l| *l == p.label).unwrap_or("surface");
                let boundary = p.boundary.iter().map(|&[x, y, z]| Point3::new(x, y, z)).collect();
                Surface::new(label, p.step, p.height, boundary)
            })
            .collect();
        let kind = match truth.stair.as_ref().map(|s| s.kind.as_str()) {
            Some("spiral") => SceneKind::Spiral,
            Some(_) => SceneKind::Straight,
            None => SceneKind::Box,
        };
        Scene { kind, surfaces, stair: truth.stair.clone() }
    }

    pub fn build(kind: SceneKind) -> Scene {
        match kind {
            SceneKind::Straight => straight(&StraightStair::default()),
            SceneKind::Spiral => spiral(&SpiralStair::default()),
            SceneKind::Box => box_scene(),
        }
    }
}

/// Horizontal face at height z from a counter-clockwise (seen from above) xy outline.
fn horizontal(label: &'static str, step: Option<u32>, z: f64, xy: &[[f64; 2]]) -> Surface {
    Surface::new(label, step, z, xy.iter().map(|&[x, y]| Point3::new(x, y, z)).collect())
}

/// Vertical face on the line through `start` along the horizontal unit `dir`,
/// from an (s, z) outline counter-clockwise seen from the face's right side
/// (the side `dir` x up points to).
fn vertical(label: &'static str, step: Option<u32>, start: [f64; 2], dir: [f64; 2], sz: &[[f64; 2]]) -> Surface {
    let top = sz.iter().map(|p| p[1]).fold(f64::MIN, f64::max);
    let pts = sz.iter().map(|&[s, z]| Point3::new(start[0] + s * dir[0], start[1] + s * dir[1], z)).collect();
    Surface::new(label, step, top, pts)
}

/// Vertical rectangle from xy point a to b, z in [z0, z1], facing the right of a->b.
fn vertical_quad(label: &'static str, step: Option<u32>, a: [f64; 2], b: [f64; 2], z0: f64, z1: f64) -> Surface {
    let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    let dir = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
    vertical(label, step, a, dir, &[[0.0, z0], [len, z0], [len, z1], [0.0, z1]])
}

/// A straight staircase climbing along +x from x = 0, centred on y = 0.
#[derive(Clone, Debug)]
pub struct StraightStair {
    /// Number of risers; the last one rises to the landing.
    pub steps: u32,
    pub rise: f64,
    pub going: f64,
    pub width: f64,
    pub landing_depth: f64,
}

impl Default for StraightStair {
    fn default() -> Self {
        StraightStair { steps: 8, rise: 0.15, going: 0.28, width: 1.0, landing_depth: 1.2 }
    }
}

pub fn straight(p: &StraightStair) -> Scene {
    let (n, r, g, hw) = (p.steps, p.rise, p.going, p.width / 2.0);
    let x_end = (n - 1) as f64 * g + p.landing_depth;
    let top = n as f64 * r;
    let mut s = vec![horizontal("floor", None, 0.0, &[[-6.0, -4.0], [0.0, -4.0], [0.0, 4.0], [-6.0, 4.0]])];
    for k in 1..=n {
        let x0 = (k - 1) as f64 * g;
        let (z0, z1) = ((k - 1) as f64 * r, k as f64 * r);
        // Riser k faces the walker coming from -x.
        s.push(vertical_quad("riser", Some(k), [x0, hw], [x0, -hw], z0, z1));
        let (label, x1) = if k == n { ("landing", x_end) } else { ("tread", x0 + g) };
        s.push(horizontal(label, Some(k), z1, &[[x0, -hw], [x1, -hw], [x1, hw], [x0, hw]]));
    }
    let wall_top = top + 1.2;
    // Side walls face the stair; the end wall faces the walker.
    s.push(vertical_quad("wall", None, [x_end, -hw], [0.0, -hw], 0.0, wall_top));
    s.push(vertical_quad("wall", None, [0.0, hw], [x_end, hw], 0.0, wall_top));
    s.push(vertical_quad("wall", None, [x_end, -hw], [x_end, hw], top, wall_top));
    // The stairwell opens in a wall across the room at x = 0.
    s.push(vertical_quad("wall", None, [0.0, 4.0], [0.0, hw], 0.0, wall_top));
    s.push(vertical_quad("wall", None, [0.0, -hw], [0.0, -4.0], 0.0, wall_top));
    Scene {
        kind: SceneKind::Straight,
        surfaces: s,
        stair: Some(StairTruth { kind: "straight".into(), steps: n, rise: r, going: g, width: p.width }),
    }
}

/// A spiral staircase turning counter-clockwise (seen from above) around the z axis.
#[derive(Clone, Debug)]
pub struct SpiralStair {
    pub steps: u32,
    pub rise: f64,
    /// Angle each tread turns, radians.
    pub step_angle: f64,
    pub post_radius: f64,
    pub outer_radius: f64,
    /// Angle the landing at the top spans, radians.
    pub landing_angle: f64,
    /// Radius of the walking line along which `going` is measured, m.
    pub walk_radius: f64,
}

impl Default for SpiralStair {
    fn default() -> Self {
        SpiralStair {
            steps: 12,
            rise: 0.16,
            step_angle: 22.5f64.to_radians(),
            post_radius: 0.1,
            outer_radius: 1.1,
            landing_angle: 90f64.to_radians(),
            walk_radius: 0.7,
        }
    }
}

fn polar(r: f64, a: f64) -> [f64; 2] {
    [r * a.cos(), r * a.sin()]
}

/// Arc points from angle a0 to a1 at radius r, `segments` straight pieces.
fn arc(r: f64, a0: f64, a1: f64, segments: usize) -> Vec<[f64; 2]> {
    (0..=segments).map(|i| polar(r, a0 + (a1 - a0) * i as f64 / segments as f64)).collect()
}

pub fn spiral(p: &SpiralStair) -> Scene {
    let (n, r, da, r0, r1) = (p.steps, p.rise, p.step_angle, p.post_radius, p.outer_radius);
    let top = n as f64 * r;
    let mut s = vec![horizontal("floor", None, 0.0, &[[-4.0, -4.0], [4.0, -4.0], [4.0, 4.0], [-4.0, 4.0]])];
    let sector = |a0: f64, a1: f64, segs: usize| -> Vec<[f64; 2]> {
        let mut xy = arc(r1, a0, a1, segs);
        xy.extend(arc(r0, a1, a0, 2));
        xy
    };
    // Facets of the outer face between angles a0 and a1, from the floor to z.
    let outer_facets = |s: &mut Vec<Surface>, a0: f64, a1: f64, segs: usize, z: f64, step: u32| {
        let pts = arc(r1, a0, a1, segs);
        for w in pts.windows(2) {
            // Walking a0 -> a1 counter-clockwise on the rim, outward is to the right.
            s.push(vertical_quad("side", Some(step), w[0], w[1], 0.0, z));
        }
    };
    for k in 1..=n {
        let a0 = (k - 1) as f64 * da;
        let (z0, z1) = ((k - 1) as f64 * r, k as f64 * r);
        // Riser k on the radial line at a0, facing the walker coming clockwise.
        s.push(vertical_quad("riser", Some(k), polar(r0, a0), polar(r1, a0), z0, z1));
        let (label, a1, segs) = if k == n { ("landing", a0 + p.landing_angle, 16) } else { ("tread", a0 + da, 4) };
        s.push(horizontal(label, Some(k), z1, &sector(a0, a1, segs)));
        outer_facets(&mut s, a0, a1, segs, z1, k);
        if k == n {
            s.push(vertical_quad("side", Some(k), polar(r1, a1), polar(r0, a1), 0.0, z1));
        }
    }
    let post = arc(r0, 0.0, std::f64::consts::TAU, 16);
    for w in post.windows(2) {
        s.push(vertical_quad("post", None, w[0], w[1], 0.0, top + 1.2));
    }
    Scene {
        kind: SceneKind::Spiral,
        surfaces: s,
        stair: Some(StairTruth { kind: "spiral".into(), steps: n, rise: r, going: p.walk_radius * da, width: r1 - r0 }),
    }
}

/// Where the box sits and how big it is.
pub const BOX_CENTER: [f64; 2] = [1.0, -0.45];
pub const BOX_SIZE: [f64; 3] = [0.4, 0.3, 0.25];
/// Start of the short flight in the box scene, and its steps.
const FLIGHT_X: f64 = 2.0;

pub fn box_scene() -> Scene {
    box_scene_at(BOX_CENTER)
}

/// The box scene with the box's centre at `center` (x, y): moving it between frames is how
/// tests see the map clear what is gone.
pub fn box_scene_at(center: [f64; 2]) -> Scene {
    let (n, r, g, hw, landing) = (3u32, 0.15, 0.3, 0.5, 1.0);
    let x_end = FLIGHT_X + (n - 1) as f64 * g + landing;
    // One floor under everything: the flight's solid hides the part beneath it.
    let mut s =
        vec![horizontal("floor", None, 0.0, &[[-4.0, -3.0], [x_end + 2.0, -3.0], [x_end + 2.0, 3.0], [-4.0, 3.0]])];
    // Box: top and four sides.
    let ([cx, cy], [sx, sy, sz]) = (center, BOX_SIZE);
    let (x0, x1, y0, y1) = (cx - sx / 2.0, cx + sx / 2.0, cy - sy / 2.0, cy + sy / 2.0);
    s.push(horizontal("box_top", None, sz, &[[x0, y0], [x1, y0], [x1, y1], [x0, y1]]));
    for (a, b) in [([x0, y1], [x0, y0]), ([x0, y0], [x1, y0]), ([x1, y0], [x1, y1]), ([x1, y1], [x0, y1])] {
        s.push(vertical_quad("box_side", None, a, b, 0.0, sz));
    }
    // Flight: risers, treads, landing, and the sawtooth side profile on each side.
    let mut profile = vec![[0.0, 0.0], [x_end - FLIGHT_X, 0.0], [x_end - FLIGHT_X, n as f64 * r]];
    for k in (1..=n).rev() {
        let x0 = (k - 1) as f64 * g;
        profile.push([x0, k as f64 * r]);
        profile.push([x0, (k - 1) as f64 * r]);
    }
    profile.pop(); // back at the start
    for k in 1..=n {
        let x0 = FLIGHT_X + (k - 1) as f64 * g;
        let (z0, z1) = ((k - 1) as f64 * r, k as f64 * r);
        s.push(vertical_quad("riser", Some(k), [x0, hw], [x0, -hw], z0, z1));
        let (label, x1) = if k == n { ("landing", x_end) } else { ("tread", x0 + g) };
        s.push(horizontal(label, Some(k), z1, &[[x0, -hw], [x1, -hw], [x1, hw], [x0, hw]]));
    }
    // The -y side faces -y: walk along +x there with the profile counter-clockwise seen from -y.
    s.push(vertical("side", None, [FLIGHT_X, -hw], [1.0, 0.0], &profile));
    let mirrored: Vec<[f64; 2]> = profile.iter().rev().map(|&[x, z]| [x_end - FLIGHT_X - x, z]).collect();
    s.push(vertical("side", None, [x_end, hw], [-1.0, 0.0], &mirrored));
    s.push(vertical_quad("side", None, [x_end, -hw], [x_end, hw], 0.0, n as f64 * r));
    Scene {
        kind: SceneKind::Box,
        surfaces: s,
        stair: Some(StairTruth { kind: "straight".into(), steps: n, rise: r, going: g, width: 2.0 * hw }),
    }
}
