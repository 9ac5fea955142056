//! The cameras: what the L515 and D435i drivers decide, kept apart from librealsense so it
//! is tested without hardware.
//!
//! - [`DeviceOptions`]: a sensor's options as librealsense exposes them. The real sensor
//!   implements it in [`realsense`] (feature `realsense`); tests use a fake.
//! - [`switch_emitter_off`]: the D435i's IR projector off, read back to verify.
//! - [`pick_device`]: which plugged-in camera is ours; a clear error naming the serial.
//! - [`ImuUniter`]: gyro + accel into one stream, as realsense-ros's `unite_imu_method:=2`.
//! - [`stream_with_reconnect`]: frames until the cable goes, then retries with backoff
//!   until the camera is back.

#[cfg(feature = "realsense")]
pub mod realsense;

use std::collections::VecDeque;
use std::time::Duration;

pub use crate::config::CamOption;
use crate::types::{Intrinsics, StampNs};

/// What went wrong with a camera, in words that name the camera and the setting.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error("no {what} with serial {serial} is connected (found: {found})")]
    SerialNotFound { what: &'static str, serial: String, found: String },
    #[error("no {what} is connected (found: {found})")]
    NoneConnected { what: &'static str, found: String },
    #[error("{count} {what} cameras are connected ({found}): set the serial of the one to use")]
    Ambiguous { what: &'static str, count: usize, found: String },
    #[error("{sensor}: option {option} {problem}")]
    Option { sensor: String, option: &'static str, problem: String },
    #[error("{0}")]
    Driver(String),
    #[error("no frame within {0:?}: the stream stopped")]
    Timeout(Duration),
    #[error("the recording ended")]
    Ended,
    /// The librealsense loaded at run time cannot serve: one line saying what to install.
    #[error("{0}")]
    Library(String),
}

/// A librealsense release, as `rs2_get_api_version` reports it (major * 10000 + minor * 100
/// + patch).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct LibraryVersion {
    pub major: u32,
    pub minor: u32,
    pub patch: u32,
}

impl LibraryVersion {
    /// The release polymap pins: the newest that drives both cameras (2.55.1 dropped the
    /// L500 series, the L515 among it).
    pub const PINNED: LibraryVersion = LibraryVersion { major: 2, minor: 54, patch: 2 };

    pub fn from_api(v: i32) -> LibraryVersion {
        let v = v.max(0) as u32;
        LibraryVersion { major: v / 10000, minor: v / 100 % 100, patch: v % 100 }
    }

    /// Whether this release still has the L500 series' code.
    pub fn drives_l515(self) -> bool {
        (self.major, self.minor) <= (2, 54)
    }
}

impl std::fmt::Display for LibraryVersion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// Whether polymap can work with the librealsense loaded at run time (`runtime`), having been
/// built against the headers of `headers`; `opens_l515` when the depth camera to open is an
/// L515. Refuses, in one line naming both versions and what to install, what librealsense
/// itself would refuse (another major version, or an older minor than the headers': its
/// `verify_version_compatibility`) and a library without L500 support for an L515.
pub fn check_library(runtime: LibraryVersion, headers: LibraryVersion, opens_l515: bool) -> Result<(), CameraError> {
    let pinned = LibraryVersion::PINNED;
    if runtime.major != headers.major || runtime.minor < headers.minor {
        return Err(CameraError::Library(format!(
            "librealsense {runtime} is installed but polymap was built against {headers}, which librealsense \
             refuses to pair: install librealsense {pinned} (README \"On the robot\") and rebuild polymap"
        )));
    }
    if opens_l515 && !runtime.drives_l515() {
        return Err(CameraError::Library(format!(
            "librealsense {runtime} is installed, but it cannot open the L515 (2.55 and later dropped the L500 \
             series): install librealsense {pinned} (README \"On the robot\")"
        )));
    }
    Ok(())
}

/// A sensor's options: get, set, and whether it has one at all.
pub trait DeviceOptions {
    /// The sensor's name for messages ("Stereo Module", "L500 Depth Sensor").
    fn sensor_name(&self) -> String;
    fn supports(&self, option: CamOption) -> bool;
    fn get(&self, option: CamOption) -> Option<f32>;
    fn set(&mut self, option: CamOption, value: f32) -> Result<(), String>;
}

/// Sets one option, refusing a sensor that lacks it.
pub fn set_option(sensor: &mut impl DeviceOptions, option: CamOption, value: f32) -> Result<(), CameraError> {
    let name = sensor.sensor_name();
    let err = |problem: String| CameraError::Option { sensor: name.clone(), option: option.name(), problem };
    if !sensor.supports(option) {
        return Err(err("is not supported by this sensor".into()));
    }
    sensor.set(option, value).map_err(|e| err(format!("could not be set to {value}: {e}")))
}

/// Sets the L515 options given in the config; the others keep the camera's values.
pub fn apply_l515_options(sensor: &mut impl DeviceOptions, o: &crate::config::L515Options) -> Result<(), CameraError> {
    // Stamps in the host-aligned global time domain, so they line up with VINS's poses.
    set_option(sensor, CamOption::GlobalTimeEnabled, 1.0)?;
    for (option, value) in o.as_list() {
        set_option(sensor, option, value)?;
    }
    Ok(())
}

/// Switches the IR projector off and reads it back: its dot pattern breaks VINS's
/// feature tracking, so a projector that stays on is an error, not a warning.
pub fn switch_emitter_off(sensor: &mut impl DeviceOptions) -> Result<(), CameraError> {
    set_option(sensor, CamOption::EmitterEnabled, 0.0)?;
    match sensor.get(CamOption::EmitterEnabled) {
        Some(0.0) => Ok(()),
        read => Err(CameraError::Option {
            sensor: sensor.sensor_name(),
            option: CamOption::EmitterEnabled.name(),
            problem: format!("reads back {read:?} after being set to 0: the IR projector is still on"),
        }),
    }
}

/// One camera as librealsense lists it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceEntry {
    /// "Intel RealSense L515"
    pub name: String,
    pub serial: String,
}

/// The index of our camera among those connected: the one with `serial`, or with an empty
/// serial the only one whose name contains `what` ("L515", "D435I").
pub fn pick_device(found: &[DeviceEntry], what: &'static str, serial: &str) -> Result<usize, CameraError> {
    let listed = || {
        if found.is_empty() {
            "no RealSense camera".to_string()
        } else {
            found.iter().map(|d| format!("{} {}", d.name, d.serial)).collect::<Vec<_>>().join(", ")
        }
    };
    if !serial.is_empty() {
        return found.iter().position(|d| d.serial == serial).ok_or_else(|| CameraError::SerialNotFound {
            what,
            serial: serial.into(),
            found: listed(),
        });
    }
    let ours: Vec<usize> =
        (0..found.len()).filter(|&i| found[i].name.to_uppercase().contains(&what.to_uppercase())).collect();
    match ours[..] {
        [i] => Ok(i),
        [] => Err(CameraError::NoneConnected { what, found: listed() }),
        _ => Err(CameraError::Ambiguous { what, count: ours.len(), found: listed() }),
    }
}

/// One united IMU sample: angular velocity (rad/s) and specific force (m/s²) in the IMU frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    pub stamp_ns: StampNs,
    pub gyro: [f64; 3],
    pub accel: [f64; 3],
}

/// One thing the D435i sends.
#[derive(Clone, Debug)]
pub enum D435iSample {
    /// infra1 (left, index 1) or infra2 (right, index 2), Y8.
    Infrared {
        index: u8,
        stamp_ns: StampNs,
        intrinsics: Intrinsics,
        pixels: Vec<u8>,
    },
    Imu(ImuSample),
}

/// Gyro and accel arrive as separate streams at different rates. VINS wants both in one
/// message: each gyro sample gets the accel linearly interpolated at its stamp
/// (realsense-ros's `linear_interpolation`), so gyro samples wait for the next accel.
#[derive(Debug, Default)]
pub struct ImuUniter {
    last_accel: Option<(StampNs, [f64; 3])>,
    waiting_gyro: VecDeque<(StampNs, [f64; 3])>,
    /// Stamp of the last gyro sample united.
    last_gyro: Option<StampNs>,
}

impl ImuUniter {
    /// Gyro samples before the first accel are dropped: nothing to interpolate from. So are
    /// repeats and samples going back in time (a motion pipeline hands its newest sample
    /// out again in every frameset), as `push_accel` drops them.
    pub fn push_gyro(&mut self, stamp_ns: StampNs, gyro: [f64; 3]) {
        let newest = self.waiting_gyro.back().map(|&(t, _)| t).or(self.last_gyro);
        if self.last_accel.is_some_and(|(t, _)| stamp_ns >= t) && newest.is_none_or(|t| stamp_ns > t) {
            self.waiting_gyro.push_back((stamp_ns, gyro));
        }
    }

    /// The gyro samples this accel sample completes, in order.
    pub fn push_accel(&mut self, stamp_ns: StampNs, accel: [f64; 3]) -> Vec<ImuSample> {
        let mut out = Vec::new();
        if let Some((t0, a0)) = self.last_accel {
            if stamp_ns <= t0 {
                return out; // out of order: keep the stream monotonic
            }
            while let Some(&(t, g)) = self.waiting_gyro.front() {
                if t > stamp_ns {
                    break;
                }
                self.waiting_gyro.pop_front();
                self.last_gyro = Some(t);
                let s = (t - t0) as f64 / (stamp_ns - t0) as f64;
                let accel = std::array::from_fn(|i| a0[i] + s * (accel[i] - a0[i]));
                out.push(ImuSample { stamp_ns: t, gyro: g, accel });
            }
        }
        self.last_accel = Some((stamp_ns, accel));
        out
    }
}

/// What happened while streaming, for the log and the status message.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamStats {
    pub frames: u64,
    /// Times the stream stopped (unplugged, USB reset) and was opened again.
    pub reconnects: u64,
}

/// Streams items (depth frames, IR and IMU batches) read from `camera` by `next` to
/// `on_item` until it returns false or a recording ends. The caller opens the camera first,
/// so a camera missing at start-up is an error reported at once. Once running, a failing
/// stream is logged and the camera reopened with `open`, with exponential backoff (from
/// `backoff.0` up to `backoff.1`), until it is back or `keep_going` says stop; the map
/// lives on meanwhile.
pub fn stream_with_reconnect<C, T>(
    mut camera: C,
    mut open: impl FnMut() -> Result<C, CameraError>,
    mut next: impl FnMut(&mut C) -> Result<T, CameraError>,
    backoff: (Duration, Duration),
    mut keep_going: impl FnMut() -> bool,
    mut on_item: impl FnMut(T) -> bool,
) -> StreamStats {
    let mut stats = StreamStats::default();
    loop {
        loop {
            match next(&mut camera) {
                Ok(item) => {
                    stats.frames += 1;
                    if !on_item(item) {
                        return stats;
                    }
                }
                Err(CameraError::Ended) => return stats,
                Err(e) => {
                    tracing::warn!("camera: {e}; reopening");
                    break;
                }
            }
        }
        drop(camera);
        let mut delay = backoff.0;
        camera = loop {
            if !keep_going() {
                return stats;
            }
            match open() {
                Ok(c) => break c,
                Err(e) => {
                    tracing::warn!("camera: {e}; retrying in {delay:?}");
                    std::thread::sleep(delay);
                    delay = (delay * 2).min(backoff.1);
                }
            }
        };
        stats.reconnects += 1;
        tracing::info!("camera back after {} reconnect(s)", stats.reconnects);
    }
}
