//! The L515 and D435i through librealsense (realsense-rust), and `.bag` playback through
//! the same code. Each camera lives on the thread that reads it; frames leave as polymap's
//! plain types.

use std::collections::HashSet;
use std::ffi::CStr;
use std::path::Path;
use std::time::Duration;

use realsense_rust::config::Config as RsConfig;
use realsense_rust::context::Context;
use realsense_rust::device::Device;
use realsense_rust::frame::{AccelFrame, DepthFrame as RsDepthFrame, FrameEx, GyroFrame, InfraredFrame};
use realsense_rust::kind::{Rs2CameraInfo, Rs2Format, Rs2Option, Rs2StreamKind};
use realsense_rust::pipeline::{ActivePipeline, InactivePipeline};
use realsense_rust::sensor::Sensor;

use super::{CamOption, CameraError, D435iSample, DeviceEntry, DeviceOptions, ImuUniter};
use crate::config::{D435iConfig, DepthSourceConfig, L515Options};
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
        CamOption::ReceiverGain => Rs2Option::DigitalGain,
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

fn driver(what: &str) -> impl Fn(anyhow::Error) -> CameraError + '_ {
    move |e| CameraError::Driver(format!("{what}: {e}"))
}

/// How librealsense names a connected camera.
fn entry(d: &Device) -> DeviceEntry {
    DeviceEntry {
        name: d.info(Rs2CameraInfo::Name).map(cstr).unwrap_or_default(),
        serial: d.info(Rs2CameraInfo::SerialNumber).map(cstr).unwrap_or_default(),
    }
}

/// Picks the streams of one pipeline.
type StreamChoice<'a> = &'a dyn Fn(&mut RsConfig) -> anyhow::Result<()>;

/// Starts one pipeline per entry of `streams` on the camera `what` with `serial` ("" = the
/// only one), after `prepare` has set its sensors' options. Separate pipelines on one
/// device: librealsense's pipeline keeps only the newest motion frame of each frameset, so
/// IMU samples sharing a pipeline with the IR images are lost.
fn start_device<const N: usize>(
    what: &'static str,
    serial: &str,
    prepare: impl FnOnce(&mut [Sensor]) -> Result<(), CameraError>,
    streams: [StreamChoice; N],
) -> Result<[ActivePipeline; N], CameraError> {
    let context = Context::new().map_err(|e| CameraError::Driver(format!("librealsense context: {e}")))?;
    let devices = context.query_devices(HashSet::new());
    let found: Vec<DeviceEntry> = devices.iter().map(entry).collect();
    let index = super::pick_device(&found, what, serial)?;
    let mut sensors = devices[index].sensors();
    prepare(&mut sensors)?;
    let serial = std::ffi::CString::new(found[index].serial.clone()).unwrap_or_default();
    let start = |streams: StreamChoice| {
        let mut config = RsConfig::new();
        config
            .enable_device_from_serial(&serial)
            .map_err(|e| CameraError::Driver(format!("{what} {serial:?}: {e}")))?;
        streams(&mut config).map_err(driver(what))?;
        let pipeline = InactivePipeline::try_from(&context).map_err(|e| CameraError::Driver(format!("{what}: {e}")))?;
        pipeline.start(Some(config)).map_err(driver(what))
    };
    let mut started = Vec::with_capacity(N);
    for s in streams {
        started.push(start(s)?);
    }
    Ok(started.try_into().unwrap_or_else(|_| unreachable!("one pipeline per entry")))
}

/// Starts a pipeline playing all of `path`'s streams once.
fn start_bag(path: &Path) -> Result<ActivePipeline, CameraError> {
    if !path.is_file() {
        return Err(CameraError::Driver(format!("bag {}: no such file", path.display())));
    }
    let fail = |e: &dyn std::fmt::Display| CameraError::Driver(format!("bag {}: {e}", path.display()));
    let context = Context::new().map_err(|e| fail(&e))?;
    let mut config = RsConfig::new();
    config.enable_device_from_file(path, false).map_err(|e| fail(&e))?;
    let pipeline = InactivePipeline::try_from(&context).map_err(|e| fail(&e))?;
    pipeline.start(Some(config)).map_err(|e| fail(&e))
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
    pipeline: ActivePipeline,
    intrinsics: Intrinsics,
    feed: Feed,
}

/// Where the frames come from; for a recording, how far its switch to every frame got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Feed {
    /// A camera only stops; it never ends.
    Camera,
    /// A recording as librealsense starts it: in real time, dropping what a busy reader misses.
    RealTimePlayback,
    /// Switched to every frame and rewound: frames left over from before the rewind are
    /// skipped until one stamped at or before `from` (the recording's start) arrives.
    Rewound { from: StampNs },
    /// Every frame, in order, until the recording ends.
    EveryFrame,
}

impl RealsenseDepth {
    /// The L515 named by `cfg.serial` (or the only one), with the configured profile and options.
    pub fn open(cfg: &DepthSourceConfig) -> Result<RealsenseDepth, CameraError> {
        let [pipeline] = start_device(
            "L515",
            &cfg.serial,
            |sensors| {
                for s in sensors.iter_mut().filter(|s| s.supports_option(Rs2Option::DepthUnits)) {
                    apply_l515_options(s, &cfg.options)?;
                }
                Ok(())
            },
            [&|c: &mut RsConfig| {
                c.disable_all_streams()?;
                let (w, h, fps) = (cfg.width as usize, cfg.height as usize, cfg.fps as usize);
                c.enable_stream(Rs2StreamKind::Depth, None, w, h, Rs2Format::Z16, fps)?;
                Ok(())
            }],
        )?;
        Self::from_pipeline(pipeline, Feed::Camera)
    }

    /// Plays a `.bag` recording (realsense-viewer's, or one made by scripts/make_bag.py)
    /// through librealsense, once.
    pub fn open_bag(path: &Path) -> Result<RealsenseDepth, CameraError> {
        Self::from_pipeline(start_bag(path)?, Feed::RealTimePlayback)
    }

    fn from_pipeline(pipeline: ActivePipeline, feed: Feed) -> Result<RealsenseDepth, CameraError> {
        let stream = pipeline
            .profile()
            .streams()
            .iter()
            .find(|s| s.kind() == Rs2StreamKind::Depth)
            .ok_or_else(|| CameraError::Driver("no depth stream".into()))?;
        let i = stream.intrinsics().map_err(|e| CameraError::Driver(format!("depth intrinsics: {e}")))?;
        let depth_scale = pipeline
            .profile()
            .device()
            .sensors()
            .iter()
            .find_map(|s| s.get_option(Rs2Option::DepthUnits))
            .ok_or_else(|| CameraError::Driver("the depth sensor reports no depth_units".into()))?;
        let intrinsics = intrinsics_of(&i, depth_scale as f64);
        if let Some(p) = intrinsics.problem() {
            return Err(CameraError::Driver(format!("the camera's intrinsics are unusable: {p}")));
        }
        Ok(RealsenseDepth { pipeline, intrinsics, feed })
    }

    /// Read from the device (or the recording), never from the config.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// The next depth frame; `Timeout` when the camera stopped sending, `Ended` at the end
    /// of a recording.
    pub fn next_frame(&mut self) -> Result<DepthFrame, CameraError> {
        loop {
            let frames = match self.pipeline.wait(Some(FRAME_TIMEOUT)) {
                Ok(f) => f,
                Err(_) if self.feed == Feed::Camera => return Err(CameraError::Timeout(FRAME_TIMEOUT)),
                Err(_) => return Err(CameraError::Ended),
            };
            let Some(depth) = frames.frames_of_type::<RsDepthFrame>().pop() else { continue };
            let stamp_ns = stamp_ns(&depth);
            match self.feed {
                Feed::RealTimePlayback => {
                    // The first frame came in real time; frames before it may be lost already.
                    play_every_frame_from_start(depth)?;
                    self.feed = Feed::Rewound { from: stamp_ns };
                    continue;
                }
                Feed::Rewound { from } if stamp_ns > from => continue,
                Feed::Rewound { .. } => self.feed = Feed::EveryFrame,
                Feed::Camera | Feed::EveryFrame => {}
            }
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
                stamp_ns,
                width: w as u32,
                height: h as u32,
                depth_scale: self.intrinsics.depth_scale,
                pixels,
            });
        }
    }
}

/// librealsense plays a recording in real time, dropping the frames a busy reader misses;
/// a recording should give every frame, the same on any machine. So on the first frame,
/// playback is switched to wait for its reader and rewound to the start (the depth stream
/// then skips what came before the rewind by its stamps). realsense-rust has no playback
/// API: this goes to the C API, through the playback device behind the frame's sensor.
fn play_every_frame_from_start(frame: RsDepthFrame) -> Result<(), CameraError> {
    use realsense_sys as sys;
    fn check(err: *mut sys::rs2_error, what: &str) -> Result<(), CameraError> {
        if err.is_null() {
            return Ok(());
        }
        // SAFETY: a non-null rs2_error from the call just made, freed once here.
        let message = unsafe {
            let m = CStr::from_ptr(sys::rs2_get_error_message(err)).to_string_lossy().into_owned();
            sys::rs2_free_error(err);
            m
        };
        Err(CameraError::Driver(format!("{what}: {message}")))
    }
    // SAFETY: we own the frame from get_owned_raw and release it; the sensor and device
    // handles made from it are deleted after use, as the C API documents.
    unsafe {
        let raw = frame.get_owned_raw();
        let mut err = std::ptr::null_mut();
        let sensor = sys::rs2_get_frame_sensor(raw.as_ptr(), &mut err);
        let mut result = check(err, "the recording's sensor");
        if result.is_ok() {
            let device = sys::rs2_create_device_from_sensor(sensor, &mut err);
            result = check(err, "the recording's device");
            if result.is_ok() {
                sys::rs2_playback_device_set_real_time(device, 0, &mut err);
                result = check(err, "switching playback off real time");
                if result.is_ok() {
                    sys::rs2_playback_seek(device, 0, &mut err);
                    result = check(err, "rewinding the recording");
                }
                sys::rs2_delete_device(device);
            }
            sys::rs2_delete_sensor(sensor);
        }
        sys::rs2_release_frame(raw.as_ptr());
        result
    }
}

/// Sets the L515 options given in the config; the others keep the camera's values.
pub fn apply_l515_options(sensor: &mut impl DeviceOptions, o: &L515Options) -> Result<(), CameraError> {
    // Stamps in the host-aligned global time domain, so they line up with VINS's poses.
    super::set_option(sensor, CamOption::GlobalTimeEnabled, 1.0)?;
    for (option, value) in o.as_list() {
        super::set_option(sensor, option, value)?;
    }
    Ok(())
}

/// The D435i: infra1 + infra2 and the united IMU, its IR projector off. Two pipelines, IR
/// and IMU (see [`start_device`]).
pub struct RealsenseD435i {
    ir: ActivePipeline,
    imu: ActivePipeline,
    uniter: ImuUniter,
    intrinsics: [Intrinsics; 2],
}

impl RealsenseD435i {
    pub fn open(cfg: &D435iConfig) -> Result<RealsenseD435i, CameraError> {
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
                &|c: &mut RsConfig| {
                    c.disable_all_streams()?;
                    let (w, h, fps) = (cfg.ir_width as usize, cfg.ir_height as usize, cfg.ir_fps as usize);
                    c.enable_stream(Rs2StreamKind::Infrared, Some(1), w, h, Rs2Format::Y8, fps)?;
                    c.enable_stream(Rs2StreamKind::Infrared, Some(2), w, h, Rs2Format::Y8, fps)?;
                    Ok(())
                },
                &|c: &mut RsConfig| {
                    c.disable_all_streams()?;
                    c.enable_stream(Rs2StreamKind::Gyro, None, 0, 0, Rs2Format::MotionXyz32F, cfg.gyro_hz as usize)?;
                    c.enable_stream(Rs2StreamKind::Accel, None, 0, 0, Rs2Format::MotionXyz32F, cfg.accel_hz as usize)?;
                    Ok(())
                },
            ],
        )?;
        let mut intrinsics = [Intrinsics::L515_320X240; 2];
        for s in ir.profile().streams().iter().filter(|s| s.kind() == Rs2StreamKind::Infrared) {
            let i = s.intrinsics().map_err(|e| CameraError::Driver(format!("IR intrinsics: {e}")))?;
            // IR images carry no depth; the scale is the D4xx's nominal 1 mm.
            intrinsics[if s.index() == 2 { 1 } else { 0 }] = intrinsics_of(&i, 0.001);
        }
        Ok(RealsenseD435i { ir, imu, uniter: ImuUniter::default(), intrinsics })
    }

    /// The next samples: IR images and the IMU samples completed so far. `Timeout` when
    /// nothing came for 2 s.
    pub fn next_samples(&mut self) -> Result<Vec<D435iSample>, CameraError> {
        let since = std::time::Instant::now();
        loop {
            let mut got = false;
            let mut out = Vec::new();
            let poll_err = |e: realsense_rust::pipeline::FrameWaitError| CameraError::Driver(format!("D435i: {e}"));
            if let std::task::Poll::Ready(frames) = self.ir.poll().map_err(poll_err)? {
                got = true;
                for f in frames.frames_of_type::<InfraredFrame>() {
                    let index = f.stream_profile().index() as u8;
                    // SAFETY: a Y8 frame holds `height` rows of `stride` bytes.
                    let pixels = unsafe { unstride::<u8>(f.get_data(), f.stride(), f.width(), f.height()) };
                    let intrinsics = self.intrinsics[if index == 2 { 1 } else { 0 }];
                    out.push(D435iSample::Infrared { index, stamp_ns: stamp_ns(&f), intrinsics, pixels });
                }
            }
            if let std::task::Poll::Ready(frames) = self.imu.poll().map_err(poll_err)? {
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
                return Err(CameraError::Timeout(FRAME_TIMEOUT));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}
