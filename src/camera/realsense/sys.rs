//! The parts of librealsense's C API that realsense-rust does not wrap: the library's version,
//! and playing a recording with real time switched off before its first frame.

use std::ffi::{CStr, CString};
use std::path::Path;
use std::ptr::NonNull;
use std::time::Duration;

use realsense_rust::frame::CompositeFrame;
use realsense_rust::kind::{Rs2Format, Rs2StreamKind};
use realsense_rust::pipeline::PipelineProfile;
use realsense_sys as sys;

use crate::camera::{CameraError, LibraryVersion};

/// `Err` with librealsense's message when `err` is set (and frees it), naming `what` was tried.
pub(super) fn check(err: *mut sys::rs2_error, what: &str) -> Result<(), CameraError> {
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

/// The librealsense loaded at run time (not the one polymap was built against).
pub fn library_version() -> Result<LibraryVersion, CameraError> {
    let mut err = std::ptr::null_mut();
    // SAFETY: no arguments but the error slot.
    let v = unsafe { sys::rs2_get_api_version(&mut err) };
    check(err, "reading librealsense's version")?;
    Ok(LibraryVersion::from_api(v))
}

/// The librealsense headers polymap was built against.
pub fn header_version() -> LibraryVersion {
    LibraryVersion::from_api(sys::RS2_API_VERSION as i32)
}

/// The start-up check ([`crate::camera::check_library`]) against the library loaded now.
pub fn check_loaded_library(opens_l515: bool) -> Result<(), CameraError> {
    crate::camera::check_library(library_version()?, header_version(), opens_l515)
}

/// Held while librealsense makes, starts, queries or deletes a context and what it opened (a
/// camera's or a recording's), so that this process does so one thread at a time. Two
/// contexts made at once on two threads (the L515's and the D435i's, opened side by side at
/// start-up) race in librealsense's USB layer (libusb's initialisation and device list,
/// librealsense issues 12280 and 12400); the RealSense tests, whose live-camera and playback
/// tests overlap, once died of a corrupted heap in about a dozen CI runs. Reentrant on one
/// thread: a start that fails half way deletes what it made with the lock still held.
pub(super) struct ContextLock(Option<std::sync::MutexGuard<'static, ()>>);

thread_local! {
    /// Whether this thread holds the context lock.
    static HOLDS_CONTEXT_LOCK: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

pub(super) fn one_context_at_a_time() -> ContextLock {
    static CONTEXTS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    if HOLDS_CONTEXT_LOCK.get() {
        return ContextLock(None);
    }
    let guard = CONTEXTS.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    HOLDS_CONTEXT_LOCK.set(true);
    ContextLock(Some(guard))
}

impl Drop for ContextLock {
    fn drop(&mut self) {
        if self.0.is_some() {
            HOLDS_CONTEXT_LOCK.set(false);
        }
    }
}

/// One stream a pipeline should deliver; zero sizes and rates take what there is.
#[derive(Clone, Copy, Debug)]
pub(super) struct StreamRequest {
    pub kind: Rs2StreamKind,
    /// The stream's index (infra 1 or 2), None for any.
    pub index: Option<usize>,
    pub width: usize,
    pub height: usize,
    pub format: Rs2Format,
    pub fps: usize,
}

impl StreamRequest {
    /// Whatever a recording holds of `kind` (at `index`).
    pub fn any(kind: Rs2StreamKind, index: Option<usize>) -> StreamRequest {
        StreamRequest { kind, index, width: 0, height: 0, format: Rs2Format::Any, fps: 0 }
    }
}

/// A pipeline playing a `.bag` once, every frame in order: real time is switched off through
/// the device of the pipeline's profile right after it starts, before anyone reads a frame.
/// (In real time, librealsense drops what a busy reader misses; realsense-rust exposes
/// neither the playback device nor the pipeline's handle, hence the C API.) A context of its
/// own each, since librealsense loads a file into a context only once.
pub(super) struct Playback {
    // Dropped first: the pipeline holds the device too, so the device and the context are
    // deleted with the handles, under the context lock.
    profile: PipelineProfile,
    handles: Handles,
}

/// The context and pipeline, stopped and deleted on drop.
struct Handles {
    context: NonNull<sys::rs2_context>,
    pipeline: Option<NonNull<sys::rs2_pipeline>>,
}

impl Drop for Handles {
    fn drop(&mut self) {
        let _one = one_context_at_a_time();
        // SAFETY: handles this struct owns; stopping a pipeline that never started only
        // reports an error, which is ignored.
        unsafe {
            if let Some(p) = self.pipeline {
                let mut err = std::ptr::null_mut();
                sys::rs2_pipeline_stop(p.as_ptr(), &mut err);
                if !err.is_null() {
                    sys::rs2_free_error(err);
                }
                sys::rs2_delete_pipeline(p.as_ptr());
            }
            sys::rs2_delete_context(self.context.as_ptr());
        }
    }
}

// SAFETY: librealsense's pipeline and context handles may be used from any thread; a
// Playback is used by one thread at a time (it moves to the camera's thread).
unsafe impl Send for Playback {}

impl Playback {
    pub fn start(path: &Path, streams: &[StreamRequest]) -> Result<Playback, CameraError> {
        if !path.is_file() {
            return Err(CameraError::Driver(format!("bag {}: no such file", path.display())));
        }
        let what = format!("bag {}", path.display());
        let file = CString::new(path.as_os_str().as_encoded_bytes())
            .map_err(|_| CameraError::Driver(format!("{what}: a path with a NUL byte")))?;
        let mut err = std::ptr::null_mut();
        let _one = one_context_at_a_time();
        // SAFETY: every handle is checked before use and owned by `handles` (deleted with it
        // on any failure); the config is deleted once the pipeline has started with it.
        unsafe {
            let context = sys::rs2_create_context(sys::RS2_API_VERSION as i32, &mut err);
            check(err, &what)?;
            let mut handles =
                Handles { context: NonNull::new(context).expect("a context or an error"), pipeline: None };
            let pipeline = sys::rs2_create_pipeline(context, &mut err);
            check(err, &what)?;
            handles.pipeline = NonNull::new(pipeline);
            let config = sys::rs2_create_config(&mut err);
            check(err, &what)?;
            let started = (|| {
                sys::rs2_config_enable_device_from_file_repeat_option(config, file.as_ptr(), 0, &mut err);
                check(err, &what)?;
                for s in streams {
                    let index = s.index.map_or(-1, |i| i as i32);
                    let (kind, format) = (s.kind as sys::rs2_stream, s.format as sys::rs2_format);
                    let (w, h, fps) = (s.width as i32, s.height as i32, s.fps as i32);
                    sys::rs2_config_enable_stream(config, kind, index, w, h, format, fps, &mut err);
                    check(err, &format!("{what}: stream {:?} {:?}", s.kind, s.index))?;
                }
                let profile = sys::rs2_pipeline_start_with_config(pipeline, config, &mut err);
                check(err, &what)?;
                Ok::<_, CameraError>(profile)
            })();
            sys::rs2_delete_config(config);
            let profile = NonNull::new(started?).expect("a profile or an error");
            let device = sys::rs2_pipeline_profile_get_device(profile.as_ptr(), &mut err);
            let mut switched = check(err, &what);
            if switched.is_ok() {
                sys::rs2_playback_device_set_real_time(device, 0, &mut err);
                switched = check(err, &format!("{what}: switching playback off real time"));
                sys::rs2_delete_device(device);
            }
            // Takes the profile handle over (and deletes it) whether or not this succeeded.
            let profile = PipelineProfile::try_from(profile).map_err(|e| CameraError::Driver(format!("{what}: {e}")));
            switched?;
            Ok(Playback { handles, profile: profile? })
        }
    }

    pub fn profile(&self) -> &PipelineProfile {
        &self.profile
    }

    /// The next frames within `timeout`; None when none came.
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<CompositeFrame>, CameraError> {
        let mut frame = std::ptr::null_mut();
        let mut err = std::ptr::null_mut();
        let pipeline = self.pipeline();
        // SAFETY: a started pipeline; a frame it hands out is owned by the CompositeFrame.
        let got = unsafe {
            sys::rs2_pipeline_try_wait_for_frames(pipeline, &mut frame, timeout.as_millis() as u32, &mut err)
        };
        check(err, "waiting for the recording's frames")?;
        Ok((got != 0).then(|| CompositeFrame::from(NonNull::new(frame).expect("a frame when one was got"))))
    }

    /// The next frames if there are any now.
    pub fn poll(&mut self) -> Result<Option<CompositeFrame>, CameraError> {
        let mut frame = std::ptr::null_mut();
        let mut err = std::ptr::null_mut();
        let pipeline = self.pipeline();
        // SAFETY: as in `wait`.
        let got = unsafe { sys::rs2_pipeline_poll_for_frames(pipeline, &mut frame, &mut err) };
        check(err, "polling the recording's frames")?;
        Ok((got != 0).then(|| CompositeFrame::from(NonNull::new(frame).expect("a frame when one was got"))))
    }

    fn pipeline(&self) -> *mut sys::rs2_pipeline {
        self.handles.pipeline.expect("a started playback has its pipeline").as_ptr()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc;

    use super::*;
    use crate::sequence::Sequence;

    #[test]
    fn a_recording_is_opened_only_when_no_other_thread_works_a_context() {
        let dir = tempfile::tempdir().unwrap();
        let bag = dir.path().join("depth.bag");
        let seq = Sequence::open(concat!(env!("CARGO_MANIFEST_DIR"), "/mock_frames/straight_320")).unwrap();
        super::super::bag::write_l515_bag(&seq, &bag, 3).unwrap();
        let held = one_context_at_a_time();
        // Reentrant on its own thread: a failing start deletes its handles under the lock.
        drop(one_context_at_a_time());
        let (tx, rx) = mpsc::channel();
        let opener = std::thread::spawn(move || {
            let playback = Playback::start(&bag, &[StreamRequest::any(Rs2StreamKind::Depth, None)]);
            // Said before the playback is dropped, which takes the lock again.
            tx.send(playback.as_ref().map(|_| ()).map_err(|e| e.to_string())).unwrap();
            drop(playback);
        });
        assert!(
            rx.recv_timeout(Duration::from_millis(500)).is_err(),
            "the recording opened while this thread held the context lock"
        );
        drop(held);
        let opened = rx.recv_timeout(Duration::from_secs(60)).expect("opened once the lock was free");
        assert_eq!(opened, Ok(()));
        opener.join().unwrap();
        // And the lock is free again once the other thread's playback is dropped.
        assert!(!HOLDS_CONTEXT_LOCK.get());
        drop(one_context_at_a_time());
    }
}
