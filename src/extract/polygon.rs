//! A frame's planar polygons: the type handed to the map and the planners, and how
//! regions with plane fits become them (outlines ray cast onto the planes, border
//! vertices pulled in, cuts at neighbour planes, small ones dropped).

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::cpu::ransac::PlaneFit;
use super::regions::Outline;
use super::regions::{Creases, Segmentation};
use super::trim;
use super::uncertainty::{Footing, PlaneUncertainty, footing, halves_agreement, noise_lean, plane_uncertainty};
use crate::config::PipelineConfig;
use crate::grid::Grid;
use crate::ring::ring_area;
use crate::types::{Intrinsics, StampNs};

/// What an outline vertex lies on: how well the extractor knows where it is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VertexKind {
    /// On the region's pixel outline inside the image: good to a pixel or two, more at
    /// a grazing angle.
    #[default]
    Inside,
    /// On the image's border band ([`BORDER_PX`]): where the view ends, not the surface.
    ImageBorder,
    /// On the line where this polygon's plane meets a neighbour's (extract::trim): exact
    /// to the planes' fit. The neighbour's id in the same frame, None when it was too
    /// small to be published itself.
    Cut { neighbour: Option<u32> },
}

/// One planar polygon: plane n . p + d = 0 (n faces the camera), outline and holes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    pub id: u32,
    pub normal: [f64; 3],
    pub offset: f64,
    /// Area on the plane, holes excluded, m^2.
    pub area: f64,
    pub boundary: Vec<[f64; 3]>,
    pub holes: Vec<Vec<[f64; 3]>>,
    /// What each vertex of `boundary` lies on, in the same order.
    pub boundary_kinds: Vec<VertexKind>,
    /// The same for each hole.
    pub hole_kinds: Vec<Vec<VertexKind>>,
    pub pixel_count: usize,
    pub inlier_ratio: f64,
    /// RMS point-to-plane distance of the inliers, m.
    pub rms: f64,
    /// How well its plane is known (extract::uncertainty).
    pub uncertainty: PlaneUncertainty,
    /// Whether a foot may trust its plane (`uncertainty::footing`).
    #[serde(default = "Footing::unknown")]
    pub footing: Footing,
}

impl Polygon {
    /// Pixels whose centre lies inside the polygon (outline minus holes) projected into the image.
    pub fn image_mask(&self, intr: &Intrinsics) -> Vec<bool> {
        let project = |ring: &Vec<[f64; 3]>| -> Vec<[f64; 2]> {
            ring.iter()
                .map(|v| {
                    let (u, v) = intr.project(&Point3::from(*v));
                    [u, v]
                })
                .collect()
        };
        let rings: Vec<Vec<[f64; 2]>> = std::iter::once(&self.boundary).chain(&self.holes).map(project).collect();
        crate::ring::fill_rings(&rings, intr.width as usize, intr.height as usize)
    }

    /// The same polygon in another frame: `t` maps this polygon's frame into it.
    pub fn transformed(&self, t: &Isometry3<f64>) -> Polygon {
        let p = |v: &[f64; 3]| {
            let q = t * Point3::new(v[0], v[1], v[2]);
            [q.x, q.y, q.z]
        };
        let n = t.rotation * Vector3::from(self.normal);
        // A point on the plane moves with t; the offset follows from it.
        let on_plane = t * Point3::from(Vector3::from(self.normal) * -self.offset);
        Polygon {
            normal: [n.x, n.y, n.z],
            offset: -n.dot(&on_plane.coords),
            boundary: self.boundary.iter().map(p).collect(),
            holes: self.holes.iter().map(|h| h.iter().map(p).collect()).collect(),
            uncertainty: self
                .uncertainty
                .moved(|v| (t.rotation * Vector3::from(v)).into(), |v| (t * Point3::from(v)).coords.into()),
            ..self.clone()
        }
    }

    /// Area-weighted centroid of the outer boundary (holes ignored), m.
    pub fn centroid(&self) -> [f64; 3] {
        let pts: Vec<Vector3<f64>> = self.boundary.iter().map(|v| Vector3::from(*v)).collect();
        let mut acc = Vector3::zeros();
        let mut total = 0.0;
        for i in 1..pts.len().saturating_sub(1) {
            let a = (pts[i] - pts[0]).cross(&(pts[i + 1] - pts[0])).dot(&Vector3::from(self.normal)) / 2.0;
            acc += (pts[0] + pts[i] + pts[i + 1]) / 3.0 * a;
            total += a;
        }
        let c =
            if total.abs() > 1e-12 { acc / total } else { pts.iter().sum::<Vector3<f64>>() / pts.len().max(1) as f64 };
        [c.x, c.y, c.z]
    }
}

/// Why a polygon was held back rather than published.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldBack {
    /// Smaller than `min_polygon_area_m2` once outlined.
    TooSmall,
    /// Its inliers do not fix a plane (too few, or on a line).
    NoPlane,
    /// Its two halves bend by more than `max_halves_bend_deg` (and their noise).
    NotOnePlane,
}

/// A polygon held back: what it would have been, and why it was not published.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeldBack {
    pub normal: [f64; 3],
    pub area: f64,
    pub pixel_count: usize,
    pub why: HoldBack,
}

/// A frame's polygons.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FramePolygons {
    pub stamp_ns: StampNs,
    pub polygons: Vec<Polygon>,
}

/// Polygons from regions and their plane fits: keep well-supported fits, ray cast the
/// pixel outlines onto the planes, cut them where the planes of the neighbours they meet
/// along a crease (`creases`) bound them, hold back what is smaller than the minimum area
/// or whose plane its inliers do not fix (returned beside them, with the reason), and
/// judge whether a foot may trust each one kept (its `footing`).
pub fn build_polygons(
    regions: &[Outline],
    fits: &[Option<PlaneFit>],
    seg: &Segmentation,
    creases: &Creases,
    depth: &Grid<f32>,
    intr: &Intrinsics,
    cfg: &PipelineConfig,
) -> (Vec<Polygon>, Vec<HeldBack>) {
    let mut out = Vec::new();
    // Each polygon's region's sample of points.
    let mut samples = Vec::new();
    // Each polygon's region label and plane fit.
    let mut labels = Vec::new();
    let mut plane_fits = Vec::new();
    for (region, fit) in regions.iter().zip(fits) {
        let Some(fit) = fit else {
            tracing::debug!("region {} ({} px): no plane fit", region.label, region.pixels);
            continue;
        };
        if fit.inlier_ratio() < cfg.ransac_min_inlier_ratio {
            tracing::debug!(
                "region {} ({} px): inlier ratio {:.3} below {}",
                region.label,
                region.pixels,
                fit.inlier_ratio(),
                cfg.ransac_min_inlier_ratio
            );
            continue;
        }
        let onto_plane = |ring: &[[f32; 2]]| -> Option<(Vec<[f64; 3]>, Vec<VertexKind>)> {
            let vertices = ring
                .iter()
                .map(|&[u, v]| ray_cast(&intr.ray(u as f64, v as f64), fit).map(|p| [p.x, p.y, p.z]))
                .collect::<Option<_>>()?;
            Some((vertices, ring.iter().map(|&px| kind_of_pixel(px, depth)).collect()))
        };
        let Some((mut boundary, boundary_kinds)) = onto_plane(&region.outer) else { continue };
        drop_border_vertices_onto_plane(
            &mut boundary,
            &boundary_kinds,
            &region.outer,
            region.label,
            seg,
            depth,
            intr,
            fit,
        );
        let (holes, hole_kinds) = region.holes.iter().filter_map(|h| onto_plane(h)).unzip();
        let n = fit.normal;
        out.push(Polygon {
            id: 0,
            normal: [n.x, n.y, n.z],
            offset: fit.offset,
            area: 0.0,
            boundary,
            holes,
            boundary_kinds,
            hole_kinds,
            pixel_count: region.pixels,
            inlier_ratio: fit.inlier_ratio(),
            rms: fit.rms,
            // Known once the polygon is kept (below): most regions are not.
            uncertainty: PlaneUncertainty::default(),
            footing: Footing::unknown(),
        });
        samples.push(&region.points);
        plane_fits.push(*fit);
        labels.push(region.label);
    }
    let meet = |a: usize, b: usize| creases.meet(labels[a], labels[b]);
    let sample_points: Vec<&[[f32; 3]]> = samples.iter().map(|s| s.points.as_slice()).collect();
    trim::trim_at_neighbour_planes(&mut out, &sample_points, meet, cfg.ransac_inlier_distance_m);
    for p in &mut out {
        let n = Vector3::from(p.normal);
        // Holes smaller than a region worth keeping are sensor dropouts, not surface gaps.
        (p.holes, p.hole_kinds) = std::mem::take(&mut p.holes)
            .into_iter()
            .zip(std::mem::take(&mut p.hole_kinds))
            .filter(|(h, _)| ring_area(h, &n) >= cfg.min_polygon_area_m2)
            .unzip();
        p.area = ring_area(&p.boundary, &n) - p.holes.iter().map(|h| ring_area(h, &n)).sum::<f64>();
    }
    // Kept: big enough, and a plane its inliers fix (not all on a line, not two surfaces
    // fitted as one); then judged whether a foot may trust it. A plane that fails is held
    // back, not refitted: its pixels do not hold a better one.
    let verdicts: Vec<Result<(), HoldBack>> = out
        .par_iter_mut()
        .zip(plane_fits.par_iter())
        .zip(samples.par_iter())
        .map(|((p, fit), sample)| {
            if p.area < cfg.min_polygon_area_m2 {
                return Err(HoldBack::TooSmall);
            }
            let dist = cfg.ransac_inlier_distance_m;
            let Some((u, cut)) = plane_uncertainty(&sample.points, sample.stride, fit, dist) else {
                return Err(HoldBack::NoPlane);
            };
            match halves_agreement(&sample.points, sample.stride, fit, dist, &cut) {
                Some(h) if h.one_surface(cfg.max_halves_bend_deg.to_radians()) => {
                    // Two leans its noise does not show: the rays' along a narrow support,
                    // and a share of a bend beyond noise, towards the cut's normal.
                    let bend = BEND_LEAN_SHARE * h.bend_beyond_noise_rad();
                    let bend_lean = u.axes.map(|e| bend * cut.across.dot(&Vector3::from(e)));
                    let ray_lean = noise_lean(&sample.points, fit, dist, &u);
                    p.uncertainty = u.with_lean(ray_lean).with_lean(bend_lean);
                    p.footing = footing(&p.uncertainty, p.pixel_count);
                    Ok(())
                }
                _ => Err(HoldBack::NotOnePlane),
            }
        })
        .collect();
    let held_back: Vec<HeldBack> = (out.iter().zip(&verdicts))
        .filter_map(|(p, v)| v.err().map(|why| (p, why)))
        .map(|(p, why)| HeldBack { normal: p.normal, area: p.area, pixel_count: p.pixel_count, why })
        .collect();
    for h in held_back.iter().filter(|h| h.why != HoldBack::TooSmall) {
        tracing::debug!("polygon of {} px, {:.3} m2 held back: {:?}", h.pixel_count, h.area, h.why);
    }
    let keep: Vec<bool> = verdicts.iter().map(Result::is_ok).collect();
    // Ids in the order kept; cuts name their neighbour by its new id.
    let mut next = 0;
    let new_id: Vec<Option<u32>> = keep
        .iter()
        .map(|&k| {
            k.then(|| {
                next += 1;
                next - 1
            })
        })
        .collect();
    let mut kept = keep.iter();
    out.retain(|_| *kept.next().expect("one flag per polygon"));
    for (id, p) in out.iter_mut().enumerate() {
        p.id = id as u32;
        for kind in p.boundary_kinds.iter_mut().chain(p.hole_kinds.iter_mut().flatten()) {
            if let VertexKind::Cut { neighbour: Some(n) } = kind {
                *kind = VertexKind::Cut { neighbour: new_id[*n as usize] };
            }
        }
    }
    (out, held_back)
}

/// A region whose halves bend by more than their noise (3 sigma) leans its whole fit by up
/// to this share of the excess (a region that took in a few rows of its neighbour tilts
/// by a fifth to a quarter of its halves' bend: bends of 2.5, 3.2, 7.4, 9.4, 13 and 21 deg
/// on the mock stairs' partial views tilted the whole fit by 0.5, 0.7, 1.8, 2.3, 2.7 and
/// 4.4 deg); the polygon's covariance counts that lean, so a bend under
/// `max_halves_bend_deg` that would still tilt it past the steppable bar marks it not
/// steppable.
pub const BEND_LEAN_SHARE: f64 = 0.25;

/// Outline vertices within this many pixels of the image's edge are on its border.
pub const BORDER_PX: i64 = 3;

/// The image pixel an outline vertex (u, v) rounds to.
fn pixel_of([u, v]: [f32; 2], w: i64, h: i64) -> (i64, i64) {
    ((u.round() as i64).clamp(0, w - 1), (v.round() as i64).clamp(0, h - 1))
}

/// What a vertex of a region's pixel outline lies on, before any cut.
fn kind_of_pixel(vertex: [f32; 2], image: &Grid<f32>) -> VertexKind {
    let (w, h) = (image.width as i64, image.height as i64);
    let (pu, pv) = pixel_of(vertex, w, h);
    if pu >= BORDER_PX && pv >= BORDER_PX && pu < w - BORDER_PX && pv < h - BORDER_PX {
        VertexKind::Inside
    } else {
        VertexKind::ImageBorder
    }
}

/// Where a region meets the image's border there are no normals to stop its growth, and
/// its pixels there can be the next surface's first (a riser above a far tread, within the
/// inlier distance of the tread's plane). Ray-cast onto the plane at a grazing angle they
/// land centimetres beyond the edge; their measured points, dropped straight onto the
/// plane, land where they are. So a border vertex moves by what dropping its pixel's point
/// instead of ray-casting it changes, when that pulls it towards the polygon's inside (a
/// pixel of the plane itself moves by its depth noise either way: only shrinking is safe).
#[allow(clippy::too_many_arguments)]
fn drop_border_vertices_onto_plane(
    boundary: &mut [[f64; 3]],
    kinds: &[VertexKind],
    outline_px: &[[f32; 2]],
    label: u32,
    seg: &Segmentation,
    depth: &Grid<f32>,
    intr: &Intrinsics,
    fit: &PlaneFit,
) {
    let (w, h) = (depth.width as i64, depth.height as i64);
    let n = boundary.len().max(1) as f64;
    let centre = boundary.iter().fold(Vector3::zeros(), |acc, v| acc + Vector3::from(*v)) / n;
    for ((vertex, &px), kind) in boundary.iter_mut().zip(outline_px).zip(kinds) {
        if *kind != VertexKind::ImageBorder {
            continue;
        }
        let (pu, pv) = pixel_of(px, w, h);
        // The region's pixel at the vertex (it lies half a pixel outside its pixels).
        let Some((x, y)) = (-1..=1)
            .flat_map(|dv| (-1..=1).map(move |du| (pu + du, pv + dv)))
            .filter(|&(x, y)| x >= 0 && y >= 0 && x < w && y < h)
            .find(|&(x, y)| {
                let i = (y * w + x) as usize;
                seg.labels.data[i] == label && depth.data[i] > 0.0
            })
        else {
            continue;
        };
        let ray = intr.ray(x as f64, y as f64);
        let measured = ray * depth.data[(y * w + x) as usize] as f64;
        let dropped = measured - fit.normal * (fit.normal.dot(&measured) + fit.offset);
        let Some(cast) = ray_cast(&ray, fit) else { continue };
        let shift = dropped - cast;
        let v3 = Vector3::from(*vertex);
        if shift.dot(&(centre - v3)) > 0.0 {
            let moved = v3 + shift;
            *vertex = [moved.x, moved.y, moved.z];
        }
    }
}

/// Where a camera ray meets a fitted plane in front of the camera.
fn ray_cast(ray: &Vector3<f64>, fit: &PlaneFit) -> Option<Vector3<f64>> {
    let t = -fit.offset / fit.normal.dot(ray);
    (t.is_finite() && t > 0.0).then(|| ray * t)
}
