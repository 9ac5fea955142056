//! The paper's scalar Kalman filter on the odometry's vertical drift.
//!
//! The state x is how far the odometry's z has drifted from the map's datum; each frame's
//! polygons are lowered by x before they are merged. A frame whose horizontal polygons
//! match the map measures x directly: their area-weighted mean height over the map's.

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriftFilter {
    /// Estimated vertical drift, m.
    pub z: f64,
    /// Its variance, m^2.
    pub var: f64,
    /// Process noise added per frame, m^2.
    pub sigma_p: f64,
    /// Variance of one measurement, m^2.
    pub sigma_m: f64,
}

impl DriftFilter {
    pub fn new(sigma_p: f64, sigma_m: f64) -> DriftFilter {
        // The map's first frame defines the datum: no drift, no doubt about it.
        DriftFilter { z: 0.0, var: 0.0, sigma_p, sigma_m }
    }

    /// Prediction: drift is a random walk, so only the doubt grows.
    pub fn predict(&mut self) {
        self.var += self.sigma_p;
    }

    /// Correction with one measurement of the drift, m.
    pub fn correct(&mut self, measured: f64) {
        let gain = self.var / (self.var + self.sigma_m);
        self.z += gain * (measured - self.z);
        self.var *= 1.0 - gain;
    }
}
