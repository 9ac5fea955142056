//! The L515 and D435i through librealsense 2.54 (realsense-rust), and `.bag` recordings of
//! either played through the same code. Each camera lives on the thread that reads it;
//! frames leave as polymap's plain types.
//!
//! - [`sys`]: what realsense-rust does not wrap: the library's version (the start-up check)
//!   and playing a recording with real time off from its first frame.
//! - [`bag`]: writing recordings with librealsense's own recorder.

pub mod bag;
mod sys;

use std::collections::HashSet;
use std::ffi::CStr;
use std::path::Path;
use std::time::Duration;

use realsense_rust::config::Config as RsConfig;
use realsense_rust::context::Context;
use realsense_rust::device::Device;
use realsense_rust::frame::{
    AccelFrame, CompositeFrame, DepthFrame as RsDepthFrame, FrameEx, GyroFrame, InfraredFrame,
};
use realsense_rust::kind::{Rs2CameraInfo, Rs2Format, Rs2Option, Rs2StreamKind};
use realsense_rust::pipeline::{ActivePipeline, InactivePipeline, PipelineProfile};
use realsense_rust::sensor::Sensor;
use sys::{Playback, StreamRequest};
pub use sys::{check_loaded_library, header_version, library_version};

use super::{CamOption, CameraError, D435iSample, DeviceEntry, DeviceOptions, ImuUniter};
use crate::config::{D435iConfig, DepthSourceConfig};
use crate::types::{DepthFrame, Intrinsics, StampNs};

/// How long a frame may take before the stream counts as stopped (the L515 sends 30 Hz).
const FRAME_TIMEOUT: Duration = Duration::from_secs(2);

fn rs_option(o: CamOption) -> Rs2Option {
    match o {
        CamOption::EmitterEnabled => Rs2Option::EmitterEnabled,
        CamOption::VisualPreset => Rs2Option::VisualPreset,
        CamOption::LaserPower => Rs2Option::LaserPower,
        CamOption::ConfidenceThreshold => Rs2Option::ConfidenceThreshold,
        CamOption::PreProcessingSharpening => Rs2Option::PreProcessingSharpening,
        CamOption::DigitalGain => Rs2Option::DigitalGain,
        CamOption::ReceiverGain => Rs2Option::AvalanchePhotoDiode,
        CamOption::MinDistance => Rs2Option::MinDistance,
        CamOption::GlobalTimeEnabled => Rs2Option::GlobalTimeEnabled,
    }
}

impl DeviceOptions for Sensor {
    fn sensor_name(&self) -> String {
        self.info(Rs2CameraInfo::Name).map(cstr).unwrap_or_else(|| "sensor".into())
    }
    fn supports(&self, option: CamOption) -> bool {
        self.supports_option(rs_option(option))
    }
    fn get(&self, option: CamOption) -> Option<f32> {
        self.get_option(rs_option(option))
    }
    fn set(&mut self, option: CamOption, value: f32) -> Result<(), String> {
        self.set_option(rs_option(option), value).map_err(|e| e.to_string())
    }
}

fn cstr(s: &CStr) -> String {
    s.to_string_lossy().into_owned()
}

/// A driver error naming what was being done.
fn driver<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> CameraError + '_ {
    move |e| CameraError::Driver(format!("{what}: {e}"))
}

/// How librealsense names a connected camera.
fn entry(d: &Device) -> DeviceEntry {
    DeviceEntry {
        name: d.info(Rs2CameraInfo::Name).map(cstr).unwrap_or_default(),
        serial: d.info(Rs2CameraInfo::SerialNumber).map(cstr).unwrap_or_default(),
    }
}

/// Starts one pipeline per entry of `streams` on the camera `what` with `serial` ("" = the
/// only one), after `prepare` has set its sensors' options. Separate pipelines on one
/// device: librealsense's pipeline keeps only the newest motion frame of each frameset, so
/// IMU samples sharing a pipeline with the IR images are lost.
fn start_device<const N: usize>(
    what: &'static str,
    serial: &str,
    prepare: impl FnOnce(&mut [Sensor]) -> Result<(), CameraError>,
    streams: [&[StreamRequest]; N],
) -> Result<[Frames; N], CameraError> {
    sys::check_loaded_library(what == L515)?;
    // Held until the context is dropped at the end, after the pipelines have started.
    let _one = sys::one_context_at_a_time();
    let context = Context::new().map_err(|e| CameraError::Driver(format!("librealsense context: {e}")))?;
    let devices = context.query_devices(HashSet::new());
    let found: Vec<DeviceEntry> = devices.iter().map(entry).collect();
    let index = super::pick_device(&found, what, serial)?;
    let mut sensors = devices[index].sensors();
    prepare(&mut sensors)?;
    let serial = std::ffi::CString::new(found[index].serial.clone()).unwrap_or_default();
    let start = |streams: &[StreamRequest]| {
        let mut config = RsConfig::new();
        config
            .enable_device_from_serial(&serial)
            .map_err(|e| CameraError::Driver(format!("{what} {serial:?}: {e}")))?;
        config.disable_all_streams().map_err(driver(what))?;
        for s in streams {
            config.enable_stream(s.kind, s.index, s.width, s.height, s.format, s.fps).map_err(driver(what))?;
        }
        let pipeline = InactivePipeline::try_from(&context).map_err(|e| CameraError::Driver(format!("{what}: {e}")))?;
        let started = pipeline.start(Some(config)).map_err(driver(what))?;
        Ok(Frames::Camera(LivePipeline(std::mem::ManuallyDrop::new(started))))
    };
    let mut started = Vec::with_capacity(N);
    for s in streams {
        started.push(start(s)?);
    }
    Ok(started.try_into().unwrap_or_else(|_| unreachable!("one pipeline per entry")))
}

/// The depth camera's name as librealsense lists it.
const L515: &str = "L515";

/// Where a camera's frame sets come from.
enum Frames {
    /// A camera, through realsense-rust's pipeline.
    Camera(LivePipeline),
    /// A recording, through the C API ([`Playback`]).
    Recording(Playback),
}

/// A camera's running pipeline, stopped and deleted (with its device and, its last user,
/// the context) under the context lock (`sys::one_context_at_a_time`).
struct LivePipeline(std::mem::ManuallyDrop<ActivePipeline>);

impl Drop for LivePipeline {
    fn drop(&mut self) {
        let _one = sys::one_context_at_a_time();
        // SAFETY: dropped once, here, and never used after.
        unsafe { std::mem::ManuallyDrop::drop(&mut self.0) }
    }
}

impl Frames {
    fn recording(path: &Path, streams: &[StreamRequest]) -> Result<Frames, CameraError> {
        sys::check_loaded_library(false)?;
        Playback::start(path, streams).map(Frames::Recording)
    }

    fn profile(&self) -> &PipelineProfile {
        match self {
            Frames::Camera(p) => p.0.profile(),
            Frames::Recording(p) => p.profile(),
        }
    }

    /// The next frame set: `Timeout` when a camera sends nothing for `timeout`, `Ended` when a
    /// recording has nothing more.
    fn wait(&mut self, timeout: Duration) -> Result<CompositeFrame, CameraError> {
        match self {
            Frames::Camera(p) => p.0.wait(Some(timeout)).map_err(|_| CameraError::Timeout(timeout)),
            Frames::Recording(p) => p.wait(timeout)?.ok_or(CameraError::Ended),
        }
    }

    /// A frame set if one is waiting.
    fn poll(&mut self) -> Result<Option<CompositeFrame>, CameraError> {
        match self {
            Frames::Camera(p) => match p.0.poll() {
                Ok(std::task::Poll::Ready(f)) => Ok(Some(f)),
                Ok(std::task::Poll::Pending) => Ok(None),
                Err(e) => Err(CameraError::Driver(e.to_string())),
            },
            Frames::Recording(p) => p.poll(),
        }
    }

    /// What nothing arriving for a while means: a stopped camera, or a recording's end.
    fn silence(&self) -> CameraError {
        match self {
            Frames::Camera(_) => CameraError::Timeout(FRAME_TIMEOUT),
            Frames::Recording(_) => CameraError::Ended,
        }
    }
}

/// A stream's pinhole intrinsics as polymap's plain type (rectified streams: no distortion).
fn intrinsics_of(i: &realsense_rust::base::Rs2Intrinsics, depth_scale: f64) -> Intrinsics {
    Intrinsics {
        width: i.width() as u32,
        height: i.height() as u32,
        fx: i.fx() as f64,
        fy: i.fy() as f64,
        cx: i.ppx() as f64,
        cy: i.ppy() as f64,
        depth_scale,
    }
}

/// The `width` x `height` pixels of an image whose rows lie `stride` bytes apart.
///
/// # Safety
/// `data` must hold `height` rows of `stride` bytes, aligned for `T`, with
/// `width * size_of::<T>() <= stride`.
unsafe fn unstride<T: Copy>(data: &std::ffi::c_void, stride: usize, width: usize, height: usize) -> Vec<T> {
    let row = stride / std::mem::size_of::<T>();
    // SAFETY: as the caller promises.
    let all = unsafe { std::slice::from_raw_parts(data as *const _ as *const T, row * height) };
    all.chunks_exact(row).flat_map(|r| &r[..width]).copied().collect()
}

/// librealsense stamps are milliseconds (f64); ours are nanoseconds.
fn stamp_ns(frame: &impl FrameEx) -> StampNs {
    (frame.timestamp() * 1e6).round().max(0.0) as StampNs
}

/// The L515's depth (or a recording of it), as `DepthFrame`s with the device's own
/// intrinsics and depth scale.
pub struct RealsenseDepth {
    frames: Frames,
    intrinsics: Intrinsics,
}

impl RealsenseDepth {
    /// The L515 named by `cfg.serial` (or the only one), with the configured profile and options.
    pub fn open(cfg: &DepthSourceConfig) -> Result<RealsenseDepth, CameraError> {
        let (w, h, fps) = (cfg.width as usize, cfg.height as usize, cfg.fps as usize);
        let depth =
            StreamRequest { kind: Rs2StreamKind::Depth, index: None, width: w, height: h, format: Rs2Format::Z16, fps };
        let [frames] = start_device(
            L515,
            &cfg.serial,
            |sensors| {
                for s in sensors.iter_mut().filter(|s| s.supports_option(Rs2Option::DepthUnits)) {
                    super::apply_l515_options(s, &cfg.options)?;
                }
                Ok(())
            },
            [&[depth]],
        )?;
        Self::from_frames(frames)
    }

    /// Plays the depth stream of a `.bag` recording (realsense-viewer's, or one written by
    /// [`bag::write_l515_bag`]) once, every frame.
    pub fn open_bag(path: &Path) -> Result<RealsenseDepth, CameraError> {
        Self::from_frames(Frames::recording(path, &[StreamRequest::any(Rs2StreamKind::Depth, None)])?)
    }

    fn from_frames(frames: Frames) -> Result<RealsenseDepth, CameraError> {
        let profile = frames.profile();
        let stream = profile
            .streams()
            .iter()
            .find(|s| s.kind() == Rs2StreamKind::Depth)
            .ok_or_else(|| CameraError::Driver("no depth stream".into()))?;
        let i = stream.intrinsics().map_err(|e| CameraError::Driver(format!("depth intrinsics: {e}")))?;
        let depth_scale = profile
            .device()
            .sensors()
            .iter()
            .find_map(|s| s.get_option(Rs2Option::DepthUnits))
            .ok_or_else(|| CameraError::Driver("the depth sensor reports no depth_units".into()))?;
        let intrinsics = intrinsics_of(&i, depth_scale as f64);
        if let Some(p) = intrinsics.problem() {
            return Err(CameraError::Driver(format!("the camera's intrinsics are unusable: {p}")));
        }
        Ok(RealsenseDepth { frames, intrinsics })
    }

    /// Read from the device (or the recording), never from the config.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// The next depth frame; `Timeout` when the camera stopped sending, `Ended` at the end
    /// of a recording.
    pub fn next_frame(&mut self) -> Result<DepthFrame, CameraError> {
        loop {
            let frames = self.frames.wait(FRAME_TIMEOUT)?;
            let Some(depth) = frames.frames_of_type::<RsDepthFrame>().pop() else { continue };
            let (w, h) = (depth.width(), depth.height());
            if w != self.intrinsics.width as usize || h != self.intrinsics.height as usize || depth.stride() < 2 * w {
                return Err(CameraError::Driver(format!(
                    "depth frame {w}x{h} (stride {}) does not match the profile",
                    depth.stride()
                )));
            }
            // SAFETY: a Z16 frame holds `height` rows of `stride` bytes, 2-byte aligned.
            let pixels = unsafe { unstride::<u16>(depth.get_data(), depth.stride(), w, h) };
            return Ok(DepthFrame {
                stamp_ns: stamp_ns(&depth),
                width: w as u32,
                height: h as u32,
                depth_scale: self.intrinsics.depth_scale,
                pixels,
            });
        }
    }
}

/// The D435i: infra1 + infra2 and the united IMU, its IR projector off. Two pipelines, IR
/// and IMU (see [`start_device`]); a recording plays the same two ways.
pub struct RealsenseD435i {
    ir: Frames,
    imu: Frames,
    uniter: ImuUniter,
    intrinsics: [Intrinsics; 2],
}

impl RealsenseD435i {
    pub fn open(cfg: &D435iConfig) -> Result<RealsenseD435i, CameraError> {
        let (w, h, fps) = (cfg.ir_width as usize, cfg.ir_height as usize, cfg.ir_fps as usize);
        let infra = |i| StreamRequest {
            kind: Rs2StreamKind::Infrared,
            index: Some(i),
            width: w,
            height: h,
            format: Rs2Format::Y8,
            fps,
        };
        let motion = |kind, fps: u32| StreamRequest {
            kind,
            index: None,
            width: 0,
            height: 0,
            format: Rs2Format::MotionXyz32F,
            fps: fps as usize,
        };
        let [ir, imu] = start_device(
            "D435I",
            &cfg.serial,
            |sensors| {
                let stereo = sensors
                    .iter_mut()
                    .find(|s| s.supports_option(Rs2Option::EmitterEnabled))
                    .ok_or_else(|| CameraError::Driver("the D435i has no sensor with an IR emitter option".into()))?;
                super::switch_emitter_off(stereo)?;
                for s in sensors.iter_mut().filter(|s| s.supports_option(Rs2Option::GlobalTimeEnabled)) {
                    super::set_option(s, CamOption::GlobalTimeEnabled, 1.0)?;
                }
                Ok(())
            },
            [
                &[infra(1), infra(2)],
                &[motion(Rs2StreamKind::Gyro, cfg.gyro_hz), motion(Rs2StreamKind::Accel, cfg.accel_hz)],
            ],
        )?;
        Self::from_frames(ir, imu)
    }

    /// Plays a D435i recording (infra1, infra2, gyro and accel) once, every frame, through
    /// the same two pipelines as the camera.
    pub fn open_bag(path: &Path) -> Result<RealsenseD435i, CameraError> {
        let any = StreamRequest::any;
        let ir =
            Frames::recording(path, &[any(Rs2StreamKind::Infrared, Some(1)), any(Rs2StreamKind::Infrared, Some(2))])?;
        let imu = Frames::recording(path, &[any(Rs2StreamKind::Gyro, None), any(Rs2StreamKind::Accel, None)])?;
        Self::from_frames(ir, imu)
    }

    fn from_frames(ir: Frames, imu: Frames) -> Result<RealsenseD435i, CameraError> {
        let mut intrinsics = [Intrinsics::L515_320X240; 2];
        for s in ir.profile().streams().iter().filter(|s| s.kind() == Rs2StreamKind::Infrared) {
            let i = s.intrinsics().map_err(|e| CameraError::Driver(format!("IR intrinsics: {e}")))?;
            // IR images carry no depth; the scale is the D4xx's nominal 1 mm.
            intrinsics[if s.index() == 2 { 1 } else { 0 }] = intrinsics_of(&i, 0.001);
        }
        Ok(RealsenseD435i { ir, imu, uniter: ImuUniter::default(), intrinsics })
    }

    /// The next samples: IR images and the IMU samples completed so far. `Timeout` when a
    /// camera sent nothing for 2 s, `Ended` when a recording has nothing more.
    pub fn next_samples(&mut self) -> Result<Vec<D435iSample>, CameraError> {
        let since = std::time::Instant::now();
        loop {
            let mut got = false;
            let mut out = Vec::new();
            if let Some(frames) = self.ir.poll()? {
                got = true;
                for f in frames.frames_of_type::<InfraredFrame>() {
                    let index = f.stream_profile().index() as u8;
                    // SAFETY: a Y8 frame holds `height` rows of `stride` bytes.
                    let pixels = unsafe { unstride::<u8>(f.get_data(), f.stride(), f.width(), f.height()) };
                    let intrinsics = self.intrinsics[if index == 2 { 1 } else { 0 }];
                    out.push(D435iSample::Infrared { index, stamp_ns: stamp_ns(&f), intrinsics, pixels });
                }
            }
            if let Some(frames) = self.imu.poll()? {
                got = true;
                // A motion pipeline repeats its newest sample of each stream in every
                // frameset; the uniter drops the repeats.
                for g in frames.frames_of_type::<GyroFrame>() {
                    let v = g.rotational_velocity();
                    self.uniter.push_gyro(stamp_ns(&g), [v[0] as f64, v[1] as f64, v[2] as f64]);
                }
                for a in frames.frames_of_type::<AccelFrame>() {
                    let v = a.acceleration();
                    let united = self.uniter.push_accel(stamp_ns(&a), [v[0] as f64, v[1] as f64, v[2] as f64]);
                    out.extend(united.into_iter().map(D435iSample::Imu));
                }
            }
            if got {
                return Ok(out);
            }
            if since.elapsed() > FRAME_TIMEOUT {
                return Err(self.ir.silence());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}
