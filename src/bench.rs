//! `polymap bench`: per-stage and end-to-end time per frame over many frames, the
//! runtime metric of REFERENCE.md (median and p99 over at least 300 frames).

use serde::Serialize;

use crate::extract::StageTimes;

/// Median and 99th percentile of one stage, ms.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Spread {
    pub median: f64,
    pub p99: f64,
}

/// Nearest-rank percentile (q in 0..=1) of unsorted values; NaN for none.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

pub fn spread(values: &[f64]) -> Spread {
    Spread { median: percentile(values, 0.5), p99: percentile(values, 0.99) }
}

/// Every stage's spread over the frames, in pipeline order, with its name.
pub fn stage_spreads(times: &[StageTimes]) -> Vec<(&'static str, Spread)> {
    let stage = |f: fn(&StageTimes) -> f64| spread(&times.iter().map(f).collect::<Vec<_>>());
    vec![
        ("upload", stage(|t| t.upload)),
        ("diffusion", stage(|t| t.diffusion)),
        ("normals", stage(|t| t.normals)),
        ("edges", stage(|t| t.edges)),
        ("regions", stage(|t| t.regions)),
        ("readback", stage(|t| t.readback)),
        ("contours", stage(|t| t.contours)),
        ("ransac", stage(|t| t.ransac)),
        ("polygons", stage(|t| t.polygons)),
        ("total", stage(|t| t.total)),
        ("gpu_busy", stage(|t| t.gpu_busy)),
    ]
}
