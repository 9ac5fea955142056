//! What the map refuses, and why: a frame polygon unfit to go in, a pose it cannot use, a
//! snapshot it cannot rebuild from. Typed, so callers and tests match on the reason; each
//! says in words what was wrong.

use nalgebra::Vector3;

use super::geometry::Moments;
use crate::extract::Polygon;
use crate::types::MAX_COORDINATE_M;

/// A polygon smaller than this is no surface (a degenerate outline), m^2.
const MIN_POLYGON_AREA_M2: f64 = 1e-6;

/// Something a frame brought that the map refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Rejection {
    #[error("polygon {id}: {problem}")]
    Polygon { id: u64, problem: PolygonProblem },
    #[error("pose at {translation:?} is not finite or beyond {max_m} m: frame skipped")]
    Pose { translation: [f64; 3], max_m: f64 },
}

/// What is wrong with a polygon.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PolygonProblem {
    #[error("normal {0:?} is not a unit vector")]
    NormalNotUnit([f64; 3]),
    #[error("offset {0} is not finite")]
    OffsetNotFinite(f64),
    #[error("outline has {0} vertices, at least 3 needed")]
    TooFewVertices(usize),
    #[error("a vertex is not finite (or beyond {MAX_COORDINATE_M} m)")]
    VertexOutOfReach,
    #[error("a hole has under 3 vertices")]
    HoleTooSmall,
    #[error(
        "vertex kinds do not match the vertices ({outline_kinds} kinds for the outline's {outline} vertices, {hole_kinds} rings of kinds for {holes} holes)"
    )]
    KindsMismatch { outline_kinds: usize, outline: usize, hole_kinds: usize, holes: usize },
    #[error("its outline encloses {0:.3e} m^2: no surface")]
    NoSurface(f64),
}

/// Why a snapshot cannot be rebuilt into a map.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SnapshotProblem {
    #[error("drift_z {z} / drift_var {var} must be finite, the variance >= 0")]
    Drift { z: f64, var: f64 },
    #[error("polygon id {0} appears twice")]
    DuplicateId(u64),
    #[error("{0}")]
    Polygon(Rejection),
}

/// Why a frame polygon cannot go into the map, if it cannot.
pub fn polygon_problem(p: &Polygon) -> Option<PolygonProblem> {
    let n = Vector3::from(p.normal);
    if !n.iter().all(|v| v.is_finite()) || (n.norm() - 1.0).abs() > 1e-3 {
        return Some(PolygonProblem::NormalNotUnit(p.normal));
    }
    if !p.offset.is_finite() {
        return Some(PolygonProblem::OffsetNotFinite(p.offset));
    }
    if p.boundary.len() < 3 {
        return Some(PolygonProblem::TooFewVertices(p.boundary.len()));
    }
    let all = p.boundary.iter().chain(p.holes.iter().flatten());
    if all.clone().any(|v| !v.iter().all(|c| c.is_finite() && c.abs() < MAX_COORDINATE_M)) {
        return Some(PolygonProblem::VertexOutOfReach);
    }
    if p.holes.iter().any(|h| h.len() < 3) {
        return Some(PolygonProblem::HoleTooSmall);
    }
    if p.boundary_kinds.len() != p.boundary.len()
        || p.hole_kinds.len() != p.holes.len()
        || p.holes.iter().zip(&p.hole_kinds).any(|(h, k)| h.len() != k.len())
    {
        return Some(PolygonProblem::KindsMismatch {
            outline_kinds: p.boundary_kinds.len(),
            outline: p.boundary.len(),
            hole_kinds: p.hole_kinds.len(),
            holes: p.holes.len(),
        });
    }
    // A degenerate outline (a line, a bowtie whose lobes cancel) has no plane frame to hold it.
    let area = Moments::of_polygon(&p.boundary, &p.holes, &n).weight;
    if !(area >= MIN_POLYGON_AREA_M2) {
        return Some(PolygonProblem::NoSurface(area));
    }
    None
}
