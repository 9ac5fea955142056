//! Writing `.bag` recordings with librealsense's own recorder, from frames made here: a
//! software device (librealsense's stand-in for a camera, fed frame by frame) wrapped in a
//! record device, the way realsense-viewer records a real camera. So tests play recordings
//! through the same driver code as the robot, and anyone can turn a sequence into a bag.
//!
//! realsense-sys does not bind librealsense's software-device API (rs_internal.h): the few
//! structs and functions used are declared below, as in librealsense 2.54's header.

use std::ffi::CString;
use std::path::Path;
use std::ptr::NonNull;

use realsense_rust::kind::{Rs2CameraInfo, Rs2Format, Rs2Option, Rs2StreamKind};
use realsense_sys as sys;

use super::sys::check;
use crate::camera::CameraError;
use crate::sequence::Sequence;
use crate::types::{Intrinsics, StampNs};

/// librealsense 2.54's rs_internal.h, the parts used here.
#[allow(non_camel_case_types)]
mod ffi {
    use std::os::raw::{c_char, c_int, c_void};

    use realsense_sys as sys;

    #[repr(C)]
    pub struct rs2_video_stream {
        pub type_: sys::rs2_stream,
        pub index: c_int,
        pub uid: c_int,
        pub width: c_int,
        pub height: c_int,
        pub fps: c_int,
        pub bpp: c_int,
        pub fmt: sys::rs2_format,
        pub intrinsics: sys::rs2_intrinsics,
    }

    #[repr(C)]
    pub struct rs2_motion_stream {
        pub type_: sys::rs2_stream,
        pub index: c_int,
        pub uid: c_int,
        pub fps: c_int,
        pub fmt: sys::rs2_format,
        pub intrinsics: sys::rs2_motion_device_intrinsic,
    }

    #[repr(C)]
    pub struct rs2_software_video_frame {
        pub pixels: *mut c_void,
        pub deleter: Option<unsafe extern "C" fn(*mut c_void)>,
        pub stride: c_int,
        pub bpp: c_int,
        pub timestamp: sys::rs2_time_t,
        pub domain: sys::rs2_timestamp_domain,
        pub frame_number: c_int,
        pub profile: *const sys::rs2_stream_profile,
        pub depth_units: f32,
    }

    #[repr(C)]
    pub struct rs2_software_motion_frame {
        pub data: *mut c_void,
        pub deleter: Option<unsafe extern "C" fn(*mut c_void)>,
        pub timestamp: sys::rs2_time_t,
        pub domain: sys::rs2_timestamp_domain,
        pub frame_number: c_int,
        pub profile: *const sys::rs2_stream_profile,
    }

    unsafe extern "C" {
        pub fn rs2_create_software_device(error: *mut *mut sys::rs2_error) -> *mut sys::rs2_device;
        pub fn rs2_software_device_register_info(
            dev: *mut sys::rs2_device,
            info: sys::rs2_camera_info,
            val: *const c_char,
            error: *mut *mut sys::rs2_error,
        );
        pub fn rs2_software_device_add_sensor(
            dev: *mut sys::rs2_device,
            name: *const c_char,
            error: *mut *mut sys::rs2_error,
        ) -> *mut sys::rs2_sensor;
        pub fn rs2_software_sensor_add_video_stream_ex(
            sensor: *mut sys::rs2_sensor,
            stream: rs2_video_stream,
            is_default: c_int,
            error: *mut *mut sys::rs2_error,
        ) -> *mut sys::rs2_stream_profile;
        pub fn rs2_software_sensor_add_motion_stream_ex(
            sensor: *mut sys::rs2_sensor,
            stream: rs2_motion_stream,
            is_default: c_int,
            error: *mut *mut sys::rs2_error,
        ) -> *mut sys::rs2_stream_profile;
        pub fn rs2_software_sensor_add_read_only_option(
            sensor: *mut sys::rs2_sensor,
            option: sys::rs2_option,
            val: f32,
            error: *mut *mut sys::rs2_error,
        );
        pub fn rs2_software_sensor_on_video_frame(
            sensor: *mut sys::rs2_sensor,
            frame: rs2_software_video_frame,
            error: *mut *mut sys::rs2_error,
        );
        pub fn rs2_software_sensor_on_motion_frame(
            sensor: *mut sys::rs2_sensor,
            frame: rs2_software_motion_frame,
            error: *mut *mut sys::rs2_error,
        );
    }
}

/// Frees what librealsense was handed with `malloc`, once it is done with it.
unsafe extern "C" fn free_c(p: *mut std::os::raw::c_void) {
    // SAFETY: every buffer handed over with this deleter came from libc::malloc.
    unsafe { libc::free(p) }
}

/// A copy of `bytes` in memory librealsense may keep and free with [`free_c`].
fn malloc_copy(bytes: &[u8]) -> *mut std::os::raw::c_void {
    // SAFETY: a fresh allocation of the right size, filled before it is handed over.
    unsafe {
        let p = libc::malloc(bytes.len().max(1));
        assert!(!p.is_null(), "out of memory copying a frame");
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), p as *mut u8, bytes.len());
        p
    }
}

/// A stream of the recording, as [`BagWriter`] hands it out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamId {
    sensor: usize,
    profile: usize,
}

struct SoftSensor {
    handle: NonNull<sys::rs2_sensor>,
    profiles: Vec<NonNull<sys::rs2_stream_profile>>,
    /// Bytes per pixel of each video profile (0 for motion).
    bpp: Vec<i32>,
    /// Where the sensor's frames go once it streams; drained after every frame.
    queue: Option<NonNull<sys::rs2_frame_queue>>,
}

/// A software camera whose streams are recorded to a `.bag` by librealsense's recorder.
/// Declare sensors and streams, [`start`](Self::start), feed frames in stamp order, then
/// [`finish`](Self::finish) (which writes the bag's index).
pub struct BagWriter {
    device: NonNull<sys::rs2_device>,
    recorder: Option<NonNull<sys::rs2_device>>,
    sensors: Vec<SoftSensor>,
    next_uid: i32,
}

/// librealsense stamps are milliseconds.
fn millis(stamp_ns: StampNs) -> f64 {
    stamp_ns as f64 * 1e-6
}

impl BagWriter {
    /// A camera that reports `name` and `serial` (realsense-viewer shows them for the recording).
    pub fn new(name: &str, serial: &str) -> Result<BagWriter, CameraError> {
        let mut err = std::ptr::null_mut();
        // SAFETY: the device is checked, then owned by the writer.
        let device = unsafe { ffi::rs2_create_software_device(&mut err) };
        check(err, "creating a software device")?;
        let writer = BagWriter {
            device: NonNull::new(device).expect("a device or an error"),
            recorder: None,
            sensors: Vec::new(),
            next_uid: 1,
        };
        for (info, value) in [(Rs2CameraInfo::Name, name), (Rs2CameraInfo::SerialNumber, serial)] {
            let value = c_string(value)?;
            // SAFETY: a live device and a NUL-terminated string librealsense copies.
            unsafe {
                ffi::rs2_software_device_register_info(device, info as sys::rs2_camera_info, value.as_ptr(), &mut err)
            };
            check(err, "naming the software device")?;
        }
        Ok(writer)
    }

    /// A sensor named as the real camera names it ("Stereo Module", "Motion Module",
    /// "L500 Depth Sensor"); returns its index.
    pub fn add_sensor(&mut self, name: &str) -> Result<usize, CameraError> {
        let name = c_string(name)?;
        let mut err = std::ptr::null_mut();
        // SAFETY: a live device; the sensor handle is owned by the writer.
        let handle = unsafe { ffi::rs2_software_device_add_sensor(self.device.as_ptr(), name.as_ptr(), &mut err) };
        check(err, "adding a sensor")?;
        let handle = NonNull::new(handle).expect("a sensor or an error");
        self.sensors.push(SoftSensor { handle, profiles: Vec::new(), bpp: Vec::new(), queue: None });
        Ok(self.sensors.len() - 1)
    }

    /// An option the recording reports with a fixed value (an L515's `depth_units`).
    pub fn add_read_only_option(&mut self, sensor: usize, option: Rs2Option, value: f32) -> Result<(), CameraError> {
        let mut err = std::ptr::null_mut();
        let handle = self.sensors[sensor].handle.as_ptr();
        // SAFETY: a live sensor of this device.
        unsafe { ffi::rs2_software_sensor_add_read_only_option(handle, option as sys::rs2_option, value, &mut err) };
        check(err, "adding an option")
    }

    /// A Z16 or Y8 image stream (`index` 0 for depth, 1 and 2 for infra1 and infra2).
    pub fn add_video_stream(
        &mut self,
        sensor: usize,
        kind: Rs2StreamKind,
        index: i32,
        intrinsics: &Intrinsics,
        format: Rs2Format,
        fps: i32,
    ) -> Result<StreamId, CameraError> {
        let bpp = match format {
            Rs2Format::Z16 => 2,
            Rs2Format::Y8 => 1,
            other => return Err(CameraError::Driver(format!("a recorded image stream in {other:?}"))),
        };
        let i = intrinsics;
        let stream = ffi::rs2_video_stream {
            type_: kind as sys::rs2_stream,
            index,
            uid: self.uid(),
            width: i.width as i32,
            height: i.height as i32,
            fps,
            bpp,
            fmt: format as sys::rs2_format,
            intrinsics: sys::rs2_intrinsics {
                width: i.width as i32,
                height: i.height as i32,
                ppx: i.cx as f32,
                ppy: i.cy as f32,
                fx: i.fx as f32,
                fy: i.fy as f32,
                model: sys::rs2_distortion_RS2_DISTORTION_NONE,
                coeffs: [0.0; 5],
            },
        };
        let mut err = std::ptr::null_mut();
        let handle = self.sensors[sensor].handle.as_ptr();
        // SAFETY: a live sensor; the profile belongs to it.
        let profile = unsafe { ffi::rs2_software_sensor_add_video_stream_ex(handle, stream, 1, &mut err) };
        check(err, "adding an image stream")?;
        Ok(self.keep_profile(sensor, profile, bpp))
    }

    /// A gyro or accel stream (MOTION_XYZ32F, rad/s or m/s²) at `fps` samples a second.
    pub fn add_motion_stream(&mut self, sensor: usize, kind: Rs2StreamKind, fps: i32) -> Result<StreamId, CameraError> {
        let mut identity = [[0.0f32; 4]; 3];
        for (k, row) in identity.iter_mut().enumerate() {
            row[k] = 1.0;
        }
        let stream = ffi::rs2_motion_stream {
            type_: kind as sys::rs2_stream,
            index: 0,
            uid: self.uid(),
            fps,
            fmt: Rs2Format::MotionXyz32F as sys::rs2_format,
            intrinsics: sys::rs2_motion_device_intrinsic {
                data: identity,
                noise_variances: [0.0; 3],
                bias_variances: [0.0; 3],
            },
        };
        let mut err = std::ptr::null_mut();
        let handle = self.sensors[sensor].handle.as_ptr();
        // SAFETY: a live sensor; the profile belongs to it.
        let profile = unsafe { ffi::rs2_software_sensor_add_motion_stream_ex(handle, stream, 1, &mut err) };
        check(err, "adding a motion stream")?;
        Ok(self.keep_profile(sensor, profile, 0))
    }

    fn uid(&mut self) -> i32 {
        self.next_uid += 1;
        self.next_uid - 1
    }

    fn keep_profile(&mut self, sensor: usize, profile: *mut sys::rs2_stream_profile, bpp: i32) -> StreamId {
        let s = &mut self.sensors[sensor];
        s.profiles.push(NonNull::new(profile).expect("a profile or an error"));
        s.bpp.push(bpp);
        StreamId { sensor, profile: s.profiles.len() - 1 }
    }

    /// Starts recording to `path`: every sensor streams all its streams into the recorder.
    pub fn start(&mut self, path: &Path) -> Result<(), CameraError> {
        let file = c_string(&path.display().to_string())?;
        let mut err = std::ptr::null_mut();
        // SAFETY: live handles; the record device, queues and open sensors are undone in Drop.
        unsafe {
            let recorder = sys::rs2_create_record_device_ex(self.device.as_ptr(), file.as_ptr(), 0, &mut err);
            check(err, &format!("recording to {}", path.display()))?;
            self.recorder = NonNull::new(recorder);
            for s in &mut self.sensors {
                let profiles: Vec<*const sys::rs2_stream_profile> =
                    s.profiles.iter().map(|p| p.as_ptr() as *const _).collect();
                sys::rs2_open_multiple(s.handle.as_ptr(), profiles.as_ptr() as *mut _, profiles.len() as i32, &mut err);
                check(err, "opening a recorded sensor")?;
                let queue = sys::rs2_create_frame_queue(1, &mut err);
                check(err, "a frame queue")?;
                s.queue = NonNull::new(queue);
                sys::rs2_start_queue(s.handle.as_ptr(), queue, &mut err);
                check(err, "starting a recorded sensor")?;
            }
        }
        Ok(())
    }

    /// One image: `pixels` holds its rows without padding.
    pub fn video_frame(
        &mut self,
        stream: StreamId,
        stamp_ns: StampNs,
        number: i32,
        pixels: &[u8],
    ) -> Result<(), CameraError> {
        let s = &self.sensors[stream.sensor];
        let (bpp, profile) = (s.bpp[stream.profile], s.profiles[stream.profile].as_ptr());
        let mut err = std::ptr::null_mut();
        let (mut width, mut height) = (0, 0);
        // SAFETY: a live video profile of this sensor.
        unsafe { sys::rs2_get_video_stream_resolution(profile, &mut width, &mut height, &mut err) };
        check(err, "reading a stream's size")?;
        if pixels.len() != (width * height * bpp) as usize {
            return Err(CameraError::Driver(format!("{} bytes for a {width}x{height} image", pixels.len())));
        }
        let frame = ffi::rs2_software_video_frame {
            pixels: malloc_copy(pixels),
            deleter: Some(free_c),
            stride: width * bpp,
            bpp,
            timestamp: millis(stamp_ns),
            domain: sys::rs2_timestamp_domain_RS2_TIMESTAMP_DOMAIN_GLOBAL_TIME,
            frame_number: number,
            profile,
            depth_units: 0.0,
        };
        // SAFETY: librealsense takes the buffer over and frees it with the deleter.
        unsafe { ffi::rs2_software_sensor_on_video_frame(s.handle.as_ptr(), frame, &mut err) };
        check(err, "recording an image")?;
        self.drain(stream.sensor)
    }

    /// One gyro (rad/s) or accel (m/s²) sample.
    pub fn motion_frame(
        &mut self,
        stream: StreamId,
        stamp_ns: StampNs,
        number: i32,
        xyz: [f32; 3],
    ) -> Result<(), CameraError> {
        let s = &self.sensors[stream.sensor];
        let bytes: Vec<u8> = xyz.iter().flat_map(|v| v.to_ne_bytes()).collect();
        let frame = ffi::rs2_software_motion_frame {
            data: malloc_copy(&bytes),
            deleter: Some(free_c),
            timestamp: millis(stamp_ns),
            domain: sys::rs2_timestamp_domain_RS2_TIMESTAMP_DOMAIN_GLOBAL_TIME,
            frame_number: number,
            profile: s.profiles[stream.profile].as_ptr(),
        };
        let mut err = std::ptr::null_mut();
        // SAFETY: librealsense takes the buffer over and frees it with the deleter.
        unsafe { ffi::rs2_software_sensor_on_motion_frame(s.handle.as_ptr(), frame, &mut err) };
        check(err, "recording a motion sample")?;
        self.drain(stream.sensor)
    }

    /// Takes the frame just fed back out of the sensor's queue: it has passed the recorder.
    fn drain(&mut self, sensor: usize) -> Result<(), CameraError> {
        let queue = self.sensors[sensor].queue.ok_or_else(|| CameraError::Driver("recording before start".into()))?;
        let mut err = std::ptr::null_mut();
        // SAFETY: a live queue; the frame it returns is released here.
        unsafe {
            let frame = sys::rs2_wait_for_frame(queue.as_ptr(), 5000, &mut err);
            check(err, "a recorded frame did not come through")?;
            sys::rs2_release_frame(frame);
        }
        Ok(())
    }

    /// Stops the sensors and closes the recording, which writes its index.
    pub fn finish(self) {}
}

impl Drop for BagWriter {
    fn drop(&mut self) {
        // SAFETY: handles the writer owns, each released once, the record device before the
        // software device it wraps.
        unsafe {
            let mut err = std::ptr::null_mut();
            let ignore = |err: &mut *mut sys::rs2_error| {
                if !err.is_null() {
                    sys::rs2_free_error(*err);
                    *err = std::ptr::null_mut();
                }
            };
            for s in &self.sensors {
                if let Some(q) = s.queue {
                    sys::rs2_stop(s.handle.as_ptr(), &mut err);
                    ignore(&mut err);
                    sys::rs2_close(s.handle.as_ptr(), &mut err);
                    ignore(&mut err);
                    sys::rs2_delete_frame_queue(q.as_ptr());
                }
            }
            if let Some(r) = self.recorder.take() {
                sys::rs2_delete_device(r.as_ptr());
            }
            for s in &self.sensors {
                sys::rs2_delete_sensor(s.handle.as_ptr());
            }
            sys::rs2_delete_device(self.device.as_ptr());
        }
    }
}

fn c_string(s: &str) -> Result<CString, CameraError> {
    CString::new(s).map_err(|_| CameraError::Driver(format!("{s:?} holds a NUL byte")))
}

/// A sequence's depth (its first `frames`, 0 = all) as an L515-like recording: one Z16
/// stream on an "L500 Depth Sensor" with the sequence's intrinsics and depth units, stamps
/// in the global time domain, as realsense-viewer records an L515.
pub fn write_l515_bag(seq: &Sequence, out: &Path, frames: usize) -> Result<(), CameraError> {
    let n = if frames == 0 { seq.len() } else { frames.min(seq.len()) };
    let stamps: Vec<StampNs> = seq.poses[..n].iter().map(|p| p.stamp_ns).collect();
    let fps = match stamps[..] {
        [first, .., last] => ((n - 1) as f64 / ((last - first) as f64 * 1e-9)).round() as i32,
        _ => 30,
    };
    let mut bag = BagWriter::new("Intel RealSense L515 (polymap synthetic)", "f0000000")?;
    let sensor = bag.add_sensor("L500 Depth Sensor")?;
    bag.add_read_only_option(sensor, Rs2Option::DepthUnits, seq.intrinsics.depth_scale as f32)?;
    let depth = bag.add_video_stream(sensor, Rs2StreamKind::Depth, 0, &seq.intrinsics, Rs2Format::Z16, fps)?;
    bag.start(out)?;
    for (k, &stamp) in stamps.iter().enumerate() {
        let frame = seq.depth(k).map_err(|e| CameraError::Driver(e.to_string()))?;
        let bytes: Vec<u8> = frame.pixels.iter().flat_map(|d| d.to_ne_bytes()).collect();
        bag.video_frame(depth, stamp, k as i32, &bytes)?;
    }
    bag.finish();
    Ok(())
}

/// What a D435i records: the IR pair (Y8) and the IMU's two streams, each in its own order.
#[derive(Clone, Debug, Default)]
pub struct D435iRecording {
    /// Both IR streams' intrinsics (rectified: the pair shares them).
    pub ir_intrinsics: Option<Intrinsics>,
    pub ir_fps: i32,
    /// Stamp and the (infra1, infra2) images, rows without padding.
    pub ir: Vec<(StampNs, [Vec<u8>; 2])>,
    pub gyro_hz: i32,
    pub gyro: Vec<(StampNs, [f32; 3])>,
    pub accel_hz: i32,
    pub accel: Vec<(StampNs, [f32; 3])>,
}

/// A D435i-like recording: a "Stereo Module" with infra1 and infra2, and a "Motion Module"
/// with gyro and accel as separate streams at their own rates, all fed in stamp order.
pub fn write_d435i_bag(rec: &D435iRecording, out: &Path) -> Result<(), CameraError> {
    let intr = rec.ir_intrinsics.ok_or_else(|| CameraError::Driver("a D435i recording needs IR intrinsics".into()))?;
    let mut bag = BagWriter::new("Intel RealSense D435I (polymap synthetic)", "843112070000")?;
    let stereo = bag.add_sensor("Stereo Module")?;
    let infra = [
        bag.add_video_stream(stereo, Rs2StreamKind::Infrared, 1, &intr, Rs2Format::Y8, rec.ir_fps)?,
        bag.add_video_stream(stereo, Rs2StreamKind::Infrared, 2, &intr, Rs2Format::Y8, rec.ir_fps)?,
    ];
    let motion = bag.add_sensor("Motion Module")?;
    let gyro = bag.add_motion_stream(motion, Rs2StreamKind::Gyro, rec.gyro_hz)?;
    let accel = bag.add_motion_stream(motion, Rs2StreamKind::Accel, rec.accel_hz)?;
    bag.start(out)?;
    // Merged by stamp, as the camera would deliver them.
    enum Item<'a> {
        Ir(usize, &'a [Vec<u8>; 2]),
        Gyro(usize, [f32; 3]),
        Accel(usize, [f32; 3]),
    }
    let mut items: Vec<(StampNs, Item)> = Vec::new();
    items.extend(rec.ir.iter().enumerate().map(|(k, (t, pair))| (*t, Item::Ir(k, pair))));
    items.extend(rec.gyro.iter().enumerate().map(|(k, (t, v))| (*t, Item::Gyro(k, *v))));
    items.extend(rec.accel.iter().enumerate().map(|(k, (t, v))| (*t, Item::Accel(k, *v))));
    items.sort_by_key(|(t, _)| *t);
    for (t, item) in items {
        match item {
            Item::Ir(k, pair) => {
                for (stream, pixels) in infra.iter().zip(pair) {
                    bag.video_frame(*stream, t, k as i32, pixels)?;
                }
            }
            Item::Gyro(k, v) => bag.motion_frame(gyro, t, k as i32, v)?,
            Item::Accel(k, v) => bag.motion_frame(accel, t, k as i32, v)?,
        }
    }
    bag.finish();
    Ok(())
}
