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
//! - [`mock_d435i`]: IR images and IMU from a sequence's trajectory, no librealsense.

pub mod mock_d435i;
#[cfg(feature = "realsense")]
pub mod realsense;

use std::collections::VecDeque;
use std::time::Duration;

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
}

/// The options polymap sets, named as realsense-ros names its parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CamOption {
    EmitterEnabled,
    VisualPreset,
    LaserPower,
    ConfidenceThreshold,
    PreProcessingSharpening,
    /// The L515's receiver gain (librealsense's RS2_OPTION_DIGITAL_GAIN).
    ReceiverGain,
    MinDistance,
    GlobalTimeEnabled,
}

impl CamOption {
    pub fn name(self) -> &'static str {
        match self {
            CamOption::EmitterEnabled => "emitter_enabled",
            CamOption::VisualPreset => "visual_preset",
            CamOption::LaserPower => "laser_power",
            CamOption::ConfidenceThreshold => "confidence_threshold",
            CamOption::PreProcessingSharpening => "pre_processing_sharpening",
            CamOption::ReceiverGain => "receiver_gain",
            CamOption::MinDistance => "min_distance",
            CamOption::GlobalTimeEnabled => "global_time_enabled",
        }
    }
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
