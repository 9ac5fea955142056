//! Percentiles of measured times: the benchmarks' and the live mapper's latency alike.

use serde::Serialize;

/// Median and 99th percentile of a set of times, ms.
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
