//! The wall clock every stamp polymap makes is on: nanoseconds since the UNIX epoch, as
//! librealsense's global time domain and VINS's ROS stamps are.

use std::time::{SystemTime, UNIX_EPOCH};

use crate::types::StampNs;

/// Now, in nanoseconds since the UNIX epoch.
pub fn now_ns() -> StampNs {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as StampNs)
}
