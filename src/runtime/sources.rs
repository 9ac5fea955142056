//! Where the frames come from, and where the D435i's streams go: the mock or the real L515
//! (or a recording of one) into the newest-frame slot, and the mock or the real D435i out to
//! VINS on realsense-ros's topics.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::{Result, anyhow, bail};

use super::slot::Slot;
use super::status::Counters;
use crate::camera::D435iSample;
use crate::config::{Config, D435iKind, DepthSourceKind};
use crate::interface::convert;
use crate::interface::wires::{Out, Wires};
use crate::ros2::msg::{CameraInfo, Image, Imu};
use crate::sequence::Sequence;

/// The sequence the mocks replay, for a mock depth source (None for a camera or a bag).
pub fn mock_sequence(config: &Config) -> Result<Option<Sequence>> {
    match config.sources.depth.kind {
        DepthSourceKind::Mock => Ok(Some(Sequence::open(&config.sources.depth.sequence)?)),
        DepthSourceKind::Realsense | DepthSourceKind::Bag | DepthSourceKind::Ros => Ok(None),
        DepthSourceKind::Sequence => bail!(
            "sources.depth.kind = \"sequence\" is for offline work (polymap replay); live needs mock, realsense or bag"
        ),
    }
}

/// Starts the depth source feeding `slot`; a camera that cannot be opened is the error.
pub async fn start_depth(
    config: &Config,
    seq: Option<&Sequence>,
    wires: &Wires,
    slot: Arc<Slot>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
) -> Result<tokio::task::JoinHandle<()>> {
    match (seq, config.sources.depth.kind) {
        (Some(seq), _) => {
            crate::mock::depth::spawn(seq, config.sources.depth.fps, stop, move |f| slot.offer(f, &counters))
        }
        (None, DepthSourceKind::Ros) => ros_depth(config, wires, slot, counters).await,
        (None, _) => realsense_depth(&config.sources.depth, slot, stop, counters).await,
    }
}

/// Depth from a ROS image topic, paired with the newest camera_info. An image that is not a
/// depth image or does not fit its camera_info is refused, logged and counted as a frame
/// not extracted; one before any camera_info waits for it (logged once).
async fn ros_depth(
    config: &Config,
    wires: &Wires,
    slot: Arc<Slot>,
    counters: Arc<Counters>,
) -> Result<tokio::task::JoinHandle<()>> {
    use std::sync::atomic::Ordering;

    use parking_lot::Mutex;

    let info: Arc<Mutex<Option<CameraInfo>>> = Arc::default();
    let newest = info.clone();
    let mut held = wires
        .subscribe(
            |i| Some(&i.depth.camera_info),
            move |topic, m| match m {
                Ok(m) => *newest.lock() = Some(m),
                Err(e) => tracing::warn!("{topic}: not a camera_info: {e}"),
            },
        )
        .await?;
    let unit_m = Some(config.sources.depth.image_unit_m).filter(|&u| u > 0.0);
    let waiting_said = AtomicBool::new(false);
    held.extend(
        wires
            .subscribe(
                |i| Some(&i.depth.image),
                move |topic, m| {
                    let frame = m.map_err(|e| e.to_string()).and_then(|image| match &*info.lock() {
                        Some(info) => convert::depth_frame(&image, info, unit_m).map(Some),
                        None => Ok(None),
                    });
                    match frame {
                        Ok(Some(frame)) => slot.offer(frame, &counters),
                        Ok(None) => {
                            if !waiting_said.swap(true, Ordering::Relaxed) {
                                tracing::info!("{topic}: waiting for its camera_info");
                            }
                        }
                        Err(why) => {
                            let n = counters.extraction_failed.fetch_add(1, Ordering::Relaxed) + 1;
                            if n <= 10 || n.is_multiple_of(1000) {
                                tracing::warn!("{topic}: image refused ({n} so far): {why}");
                            }
                        }
                    }
                },
            )
            .await?,
    );
    tracing::info!("depth from {} and {}", config.sources.depth.image_topic, config.sources.depth.camera_info_topic);
    // The subscriptions live as long as this task.
    Ok(tokio::spawn(async move {
        let _held = held;
        std::future::pending::<()>().await
    }))
}

/// The L515 (or a bag) on a thread of its own. Opened here, so a missing camera stops
/// start-up with an error naming it; later failures reconnect with backoff.
#[cfg(feature = "realsense")]
async fn realsense_depth(
    source: &crate::config::DepthSourceConfig,
    slot: Arc<Slot>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
) -> Result<tokio::task::JoinHandle<()>> {
    use std::sync::atomic::Ordering;

    use anyhow::Context;

    use crate::camera::realsense::RealsenseDepth;
    let source = source.clone();
    let open = move || match source.kind {
        DepthSourceKind::Bag => RealsenseDepth::open_bag(&source.bag),
        _ => RealsenseDepth::open(&source),
    };
    let first = tokio::task::spawn_blocking(open.clone()).await?.context("opening the depth camera")?;
    tracing::info!("depth camera open: {:?}", first.intrinsics());
    Ok(tokio::task::spawn_blocking(move || {
        let next = |c: &mut RealsenseDepth| Ok((c.next_frame()?, c.intrinsics()));
        let keep_going = || !stop.load(Ordering::Relaxed);
        let stats = crate::camera::stream_with_reconnect(first, open, next, BACKOFF, keep_going, |frame| {
            slot.offer(frame, &counters);
            !stop.load(Ordering::Relaxed)
        });
        tracing::info!("depth camera stopped: {} frames, {} reconnects", stats.frames, stats.reconnects);
    }))
}

/// Reopening a camera that stopped: first after 250 ms, doubling up to 5 s.
#[cfg(feature = "realsense")]
const BACKOFF: (std::time::Duration, std::time::Duration) =
    (std::time::Duration::from_millis(250), std::time::Duration::from_secs(5));

#[cfg(not(feature = "realsense"))]
async fn realsense_depth(
    source: &crate::config::DepthSourceConfig,
    _: Arc<Slot>,
    _: Arc<AtomicBool>,
    _: Arc<Counters>,
) -> Result<tokio::task::JoinHandle<()>> {
    bail!("sources.depth.kind = {:?} needs polymap built with --features realsense", source.kind)
}

/// The D435i's IR and IMU out for VINS: the mock along the mock camera's sequence, or the
/// real camera with its emitter off. None when `sources.d435i.kind = none`.
pub async fn start_d435i(
    config: &Config,
    seq: Option<&Sequence>,
    wires: &Wires,
    stop: Arc<AtomicBool>,
) -> Result<Option<tokio::task::JoinHandle<()>>> {
    use crate::mock::d435i::MockD435i;
    let cfg = config.sources.d435i.clone();
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    match cfg.kind {
        D435iKind::None => return Ok(None),
        D435iKind::Mock => {
            let seq =
                seq.ok_or_else(|| anyhow!("sources.d435i.kind = \"mock\" needs the mock depth camera's sequence"))?;
            let extrinsic = crate::pose::extrinsic(config);
            let mock = MockD435i::from_sequence(seq, &extrinsic, &cfg).map_err(|e| anyhow!("mock D435i: {e}"))?;
            let clock = crate::mock::SequenceClock::new(seq)?;
            let run_cfg = cfg.clone();
            tokio::spawn(async move { mock.run(clock, &run_cfg, tx).await });
        }
        D435iKind::Realsense => real_d435i(&cfg, tx, stop).await?,
    }
    let mut infra = Vec::new();
    for index in 0..2 {
        infra.push((
            wires.publisher(|i| Some(&i.infra[index].image)).await?,
            wires.publisher(|i| Some(&i.infra[index].camera_info)).await?,
        ));
    }
    let imu = wires.publisher(|i| Some(&i.imu)).await?;
    Ok(Some(tokio::spawn(async move {
        if let Err(e) = publish_d435i(&infra, &imu, &cfg, rx).await {
            tracing::warn!("D435i publishing stopped: {e:#}");
        }
    })))
}

/// Publishes the D435i's samples (real or mock, the same way) as realsense-ros does: each
/// IR image with its camera info, and the united IMU.
async fn publish_d435i(
    infra: &[(Out<Image>, Out<CameraInfo>)],
    imu: &Out<Imu>,
    cfg: &crate::config::D435iConfig,
    mut samples: tokio::sync::mpsc::Receiver<D435iSample>,
) -> Result<()> {
    use crate::mock::d435i::BASELINE_M;
    while let Some(sample) = samples.recv().await {
        match sample {
            D435iSample::Infrared { index, stamp_ns, intrinsics, pixels } => {
                let (image, info) = &infra[if index == 2 { 1 } else { 0 }];
                info.put(&convert::ir_camera_info(stamp_ns, index, &intrinsics, BASELINE_M)).await?;
                image.put(&convert::ir_image(stamp_ns, index, &intrinsics, pixels)).await?;
            }
            D435iSample::Imu(s) => imu.put(&convert::imu(&s, cfg.angular_velocity_cov, cfg.linear_accel_cov)).await?,
        }
    }
    Ok(())
}

/// The real D435i on its own thread: opened (emitter off, verified) before start-up goes
/// on; a stream that stops is reopened with backoff.
#[cfg(feature = "realsense")]
async fn real_d435i(
    cfg: &crate::config::D435iConfig,
    tx: tokio::sync::mpsc::Sender<D435iSample>,
    stop: Arc<AtomicBool>,
) -> Result<()> {
    use std::sync::atomic::Ordering;

    use anyhow::Context;

    use crate::camera::realsense::RealsenseD435i;
    let open_cfg = cfg.clone();
    let first =
        tokio::task::spawn_blocking(move || RealsenseD435i::open(&open_cfg)).await?.context("opening the D435i")?;
    let cfg = cfg.clone();
    std::thread::Builder::new().name("d435i".into()).spawn(move || {
        let open = || RealsenseD435i::open(&cfg);
        let keep_going = || !stop.load(Ordering::Relaxed);
        let send = |samples: Vec<_>| samples.into_iter().all(|s| tx.blocking_send(s).is_ok()) && keep_going();
        let stats =
            crate::camera::stream_with_reconnect(first, open, RealsenseD435i::next_samples, BACKOFF, keep_going, send);
        tracing::info!("D435i stopped: {} batches, {} reconnects", stats.frames, stats.reconnects);
    })?;
    Ok(())
}

#[cfg(not(feature = "realsense"))]
async fn real_d435i(
    _: &crate::config::D435iConfig,
    _: tokio::sync::mpsc::Sender<D435iSample>,
    _: Arc<AtomicBool>,
) -> Result<()> {
    bail!("sources.d435i.kind = \"realsense\" needs polymap built with --features realsense")
}
