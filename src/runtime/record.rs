//! `polymap record`: every frame the live session maps, with the pose it was mapped with,
//! written as a sequence on a thread of its own, so `polymap replay` of the recording makes
//! the live session's map bit for bit (same config). The map thread hands frames over a
//! short queue and waits when the disk is behind: a frame is never mapped but not recorded.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender};
use std::time::Instant;

use anyhow::{Context, Result, bail};

use crate::sequence::SequenceWriter;
use crate::types::{DepthFrame, Intrinsics, Pose};

/// Where a recording goes and when it ends.
#[derive(Clone, Debug)]
pub struct RecordOptions {
    pub dir: PathBuf,
    /// Frames after which the session ends.
    pub max_frames: Option<u64>,
    /// Bytes of depth PNGs after which the session ends.
    pub max_bytes: Option<u64>,
}

/// What a recording holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Recorded {
    pub frames: u64,
    pub bytes: u64,
}

/// Frames the map thread may be ahead of the disk.
const QUEUE: usize = 16;

/// The map thread's end of a recording.
pub struct Recorder {
    tx: SyncSender<(DepthFrame, Intrinsics, Pose)>,
    bytes: Arc<AtomicU64>,
    sent: u64,
    options: RecordOptions,
}

/// The writer thread of a recording; `finish` waits for it.
pub struct RecordingThread(std::thread::JoinHandle<Result<Recorded>>);

impl Recorder {
    /// Starts the writer thread; the sequence directory is made with the first frame.
    pub fn start(options: RecordOptions) -> Result<(Recorder, RecordingThread)> {
        if options.dir.join("poses.txt").exists() {
            bail!("{}: holds a sequence already; record into a new directory", options.dir.display());
        }
        let (tx, rx) = std::sync::mpsc::sync_channel(QUEUE);
        let bytes = Arc::new(AtomicU64::new(0));
        let (dir, written) = (options.dir.clone(), bytes.clone());
        let thread = std::thread::Builder::new().name("recorder".into()).spawn(move || write(dir, rx, written))?;
        Ok((Recorder { tx, bytes, sent: 0, options }, RecordingThread(thread)))
    }

    /// Records a frame mapped with `world_camera`. False once the recording is full (the
    /// session then ends) or its thread has stopped (it says why when finished).
    pub fn record(&mut self, frame: DepthFrame, intrinsics: Intrinsics, world_camera: Pose) -> bool {
        let full = self.options.max_frames.is_some_and(|n| self.sent >= n)
            || self.options.max_bytes.is_some_and(|n| self.bytes.load(Ordering::Relaxed) >= n);
        if full || self.tx.send((frame, intrinsics, world_camera)).is_err() {
            return false;
        }
        self.sent += 1;
        self.options.max_frames.is_none_or(|n| self.sent < n)
    }
}

impl RecordingThread {
    /// Waits for the last frame to be written, then writes poses.txt.
    pub fn finish(self) -> Result<Recorded> {
        self.0.join().map_err(|_| anyhow::anyhow!("the recorder thread panicked"))?
    }
}

/// The writer thread: frames in until the map thread drops its end, then poses.txt.
fn write(dir: PathBuf, rx: Receiver<(DepthFrame, Intrinsics, Pose)>, bytes: Arc<AtomicU64>) -> Result<Recorded> {
    let mut writer: Option<SequenceWriter> = None;
    let mut out = Recorded::default();
    let started = Instant::now();
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_style(indicatif::ProgressStyle::with_template("{spinner} recording {msg}").expect("a valid template"));
    for (frame, intrinsics, pose) in rx {
        let w = match &mut writer {
            Some(w) => w,
            None => writer.insert(
                SequenceWriter::create(&dir, intrinsics, false)
                    .with_context(|| format!("making {}", dir.display()))?
                    .with_exact_poses(),
            ),
        };
        if *w.intrinsics() != intrinsics {
            bail!("frame {}: the camera's intrinsics changed; a sequence has one camera", out.frames);
        }
        out.bytes += w
            .push(&frame.pixels, pose, None)
            .with_context(|| format!("writing frame {} into {}", out.frames, dir.display()))?;
        out.frames += 1;
        bytes.store(out.bytes, Ordering::Relaxed);
        bar.set_message(format!(
            "{}: {} frames, {:.1} MB, {:.0} s",
            dir.display(),
            out.frames,
            out.bytes as f64 / 1e6,
            started.elapsed().as_secs_f64()
        ));
    }
    bar.finish_and_clear();
    if let Some(w) = writer {
        w.finish(None).with_context(|| format!("writing {}/poses.txt", dir.display()))?;
    }
    Ok(out)
}
