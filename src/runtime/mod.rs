//! `polymap run`: the live mapper, and `polymap demo`, the whole loop on one machine.
//!
//! ```text
//! depth source ─► newest-frame slot ─► extractor thread (extract, pose at the frame's stamp,
//!   map update) ─► FrameEvent ─► publisher ─► frame_polygons, map_updates (versioned), /tf
//! map changed, at most every period ─► map and markers (transient local), planar_terrain
//! odometry subscription ─► pose buffer      services: get_map, get_foothold      status: 1 Hz
//! D435i (mock or real) ─► infra1, infra2, imu for VINS
//! ```
//!
//! - [`slot`]: the newest-frame slot; [`worker`]: the extractor thread; [`awaiting`]: extracted
//!   frames waiting for their poses;
//! - [`sources`]: the depth source and the D435i streams; [`odometry`]: poses in;
//! - [`publish`]: what the worker made, out; [`services`]: the map and footholds on request;
//! - [`status`]: counters and the status line; [`demo`]: mock VINS and mapper together;
//! - [`router`]: `polymap router`, a Zenoh router in a process of its own.
//!
//! When extraction falls behind, the newest frame wins. An extracted frame waits (in a short
//! queue, never holding up the next extraction) for the odometry pose after its stamp, at most
//! `poses.max_wait_s`; one that cannot get a pose is skipped and counted with the reason. SIGINT / SIGTERM (or `--duration`) stop it; the map is
//! saved. A snapshot that cannot be written is logged, counted and tried again next period.

pub mod awaiting;
pub mod demo;
pub mod odometry;
pub mod publish;
pub mod record;
pub mod router;
pub mod services;
pub mod slot;
pub mod sources;
pub mod status;
pub mod worker;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use parking_lot::Mutex;

use crate::clock::now_ns;
use crate::config::Config;
use crate::interface::wires::Wires;
use crate::map::PolygonMap;
use crate::pose::PoseBuffer;
use crate::ros2::Node;
use status::Counters;
use worker::{FrameEvent, WorkerEnd};

/// Runs until SIGINT / SIGTERM or `duration`; saves the map at the end. Returns the
/// counts of the whole run, its latency over every frame published.
pub async fn run(config: &Config, duration: Option<Duration>) -> Result<status::Report> {
    Ok(run_with(config, duration, None).await?.0)
}

/// As [`run`], recording every frame mapped into `options.dir` (see [`record`]), the live
/// map at the end beside it as `map.json`; ends early when the recording is full.
pub async fn run_recording(
    config: &Config,
    duration: Option<Duration>,
    options: record::RecordOptions,
) -> Result<(status::Report, record::Recorded)> {
    let dir = options.dir.clone();
    let (report, recorded, map) = run_with(config, duration, Some(options)).await?;
    let recorded = recorded.unwrap_or_default();
    if recorded.frames > 0 {
        crate::map::persist::save_to(&map.lock().snapshot(), &dir.join("map.json"))?;
    }
    Ok((report, recorded))
}

async fn run_with(
    config: &Config,
    duration: Option<Duration>,
    record: Option<record::RecordOptions>,
) -> Result<(status::Report, Option<record::Recorded>, Arc<Mutex<PolygonMap>>)> {
    let (recorder, recording) = match record {
        Some(options) => {
            let (recorder, thread) = record::Recorder::start(options)?;
            (Some(recorder), Some(thread))
        }
        None => (None, None),
    };
    let seq = sources::mock_sequence(config)?;
    crate::map::persist::remove_stale_configured(&config.map);
    let session = crate::ros2::session::open(crate::ros2::session::config(&config.zenoh.config_file)?).await?;
    let node = Arc::new(Node::new(&session, config.ros2.node_options()).await?);
    let ros1 = match config.ros1.enabled {
        true => Some(Wires::ros1(config, &config.ros1.node_name()).await?),
        false => None,
    };
    let wires = Wires { ros2: Some(Wires::ros2(config, node)), ros1 };
    let poses =
        Arc::new(Mutex::new(PoseBuffer::with_limits(4096, crate::pose::PoseLimits::from_config(&config.poses))));
    let _odometry = odometry::subscribe(&wires, poses.clone()).await?;
    let map = Arc::new(Mutex::new(crate::map::persist::initial_map(&config.map)));
    let counters = Arc::new(Counters::default());
    let stop = Arc::new(AtomicBool::new(false));
    let slot = Arc::new(slot::Slot::default());
    let (events_tx, mut events) = tokio::sync::mpsc::channel::<FrameEvent>(8);
    let shared = worker::Shared {
        slot: slot.clone(),
        stop: stop.clone(),
        poses: poses.clone(),
        map: map.clone(),
        counters: counters.clone(),
    };
    let worker = worker::spawn(config, shared, recorder, events_tx)?;
    let camera = sources::start_depth(config, seq.as_ref(), &wires, slot, stop.clone(), counters.clone()).await?;
    let d435i = sources::start_d435i(config, seq.as_ref(), &wires, stop.clone()).await?;
    // This run's epoch: versions count from the snapshot's within it, and a client seeing a
    // new one knows the mapper restarted.
    let epoch = now_ns();
    let map_frame = &config.ros2.map_frame;
    let _services = services::serve(&wires, map.clone(), counters.clone(), epoch, map_frame).await?;
    let mut publishers = publish::Publishers::new(&wires, config, epoch).await?;
    tracing::info!(
        "polymap {} on ROS 2 ({:?}, domain {})",
        config.ros2.namespace,
        config.ros2.mode(),
        config.ros2.domain_id
    );

    let mut latencies: Vec<f64> = Vec::new();
    let mut all_latencies: Vec<f64> = Vec::new();
    let mut status_tick = tokio::time::interval(Duration::from_secs(1));
    let mut whole_map_tick = tokio::time::interval(Duration::from_secs_f64(config.ros2.whole_map_period_s));
    let mut terrain_tick = tokio::time::interval(Duration::from_secs_f64(config.planar_terrain.period_s));
    // Where the robot was at the last frame mapped (map frame): the terrain grid's centre.
    let mut robot: Option<[f64; 3]> = None;
    let mut snapshot_tick = tokio::time::interval(Duration::from_secs_f64(config.map.snapshot_period_s));
    snapshot_tick.tick().await;
    let mut signals = StopSignals::new()?;
    let deadline = async {
        match duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::pin!(deadline);
    let report = |latencies: &[f64]| {
        let p = poses.lock().counters;
        let (drift_z, len) = {
            let m = map.lock();
            (m.drift.z, m.len())
        };
        let mut r = counters.report(crate::stats::spread(latencies), p, drift_z, len);
        // A ROS 1 peer's connection or call that was refused is a refused request too.
        r.requests_refused += wires.ros1_refused();
        r
    };
    // The worker's events channel closes when the thread ends, by a stop or a panic.
    let worker_ended = loop {
        tokio::select! {
            event = events.recv() => match event {
                Some(e) => {
                    if let Err(err) = publishers.frame(&e).await {
                        tracing::warn!("publishing frame {}: {err}", e.stamp_ns);
                    }
                    robot = Some(e.robot);
                    latencies.push(now_ns().saturating_sub(e.stamp_ns) as f64 * 1e-6);
                }
                None => break true,
            },
            _ = status_tick.tick() => {
                let r = report(&latencies);
                all_latencies.append(&mut latencies);
                tracing::info!("{r}");
                if let Err(e) = publishers.status(&r).await {
                    tracing::warn!("publishing the status: {e}");
                }
            }
            _ = whole_map_tick.tick() => {
                if let Err(e) = publishers.whole_map(&map).await {
                    tracing::warn!("publishing the whole map: {e}");
                }
            }
            _ = terrain_tick.tick(), if robot.is_some() => {
                if let Err(e) = publishers.terrain(&map, robot.unwrap_or_default()).await {
                    tracing::warn!("publishing the planar terrain: {e}");
                }
            }
            _ = snapshot_tick.tick() => {
                if let Err(e) = save_snapshot(&map, config).await {
                    let n = counters.snapshots_failed.fetch_add(1, Ordering::Relaxed) + 1;
                    tracing::error!("{e:#} ({n} failed so far; trying again in {} s)", config.map.snapshot_period_s);
                }
            }
            _ = &mut deadline => break false,
            _ = signals.recv() => break false,
        }
    };
    stop.store(true, Ordering::Relaxed);
    camera.abort();
    if let Some(d435i) = d435i {
        d435i.abort();
    }
    drop(events);
    let end =
        tokio::task::spawn_blocking(move || worker.join()).await?.map_err(|_| anyhow!("the extractor thread died"))?;
    all_latencies.append(&mut latencies);
    // Its writer ends with the map thread; an error of its is said once the map is saved.
    let recorded = recording.map(|r| r.finish());
    match end {
        WorkerEnd::Panicked { during, message, map_intact: true } => {
            save_snapshot(&map, config).await.context("saving the map after the extractor thread's panic")?;
            bail!("the extractor thread panicked {during}: {message} (the map is saved)");
        }
        WorkerEnd::Panicked { during, message, map_intact: false } => bail!(
            "the extractor thread panicked {during}: {message}; the map may be half-changed, so the last snapshot saved is kept"
        ),
        WorkerEnd::RecordingEnded => tracing::info!("the recording is full: the session ends"),
        WorkerEnd::Stopped if worker_ended => tracing::warn!("the extractor thread stopped by itself"),
        WorkerEnd::Stopped => {}
    }
    save_snapshot(&map, config).await.context("saving the map at shutdown")?;
    // Unregistered so the master stops naming polymap to peers; a master that does not answer
    // must not hold up the exit (systemd gives a stop 10 s).
    if let Some((node, _)) = &wires.ros1
        && tokio::time::timeout(Duration::from_secs(2), node.shutdown()).await.is_err()
    {
        tracing::warn!("ROS 1: the master did not take the unregistrations within 2 s");
    }
    let report = report(&all_latencies);
    let recorded = recorded.transpose().context("recording")?;
    Ok((report, recorded, map))
}

/// The map snapshotted under its lock, written (slow on a full or failing disk) off it.
async fn save_snapshot(map: &Arc<Mutex<PolygonMap>>, config: &Config) -> Result<()> {
    let Some(path) = crate::map::persist::snapshot_path(&config.map).map(|p| p.to_path_buf()) else {
        return Ok(());
    };
    let snapshot = map.lock().snapshot();
    tokio::task::spawn_blocking(move || crate::map::persist::save_to(&snapshot, &path)).await?
}

/// SIGINT and SIGTERM, listened for from its making on: a signal that comes while the loop
/// is busy elsewhere is kept for the next wait, not lost as a fresh `ctrl_c()` would lose it.
pub struct StopSignals {
    interrupt: tokio::signal::unix::Signal,
    terminate: tokio::signal::unix::Signal,
}

impl StopSignals {
    pub fn new() -> std::io::Result<StopSignals> {
        use tokio::signal::unix::{SignalKind, signal};
        Ok(StopSignals { interrupt: signal(SignalKind::interrupt())?, terminate: signal(SignalKind::terminate())? })
    }

    /// The next SIGINT or SIGTERM (or one that came since the last).
    pub async fn recv(&mut self) {
        tokio::select! {
            _ = self.interrupt.recv() => {}
            _ = self.terminate.recv() => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::StopSignals;

    /// A SIGINT that comes while nothing waits for it (the run loop busy publishing) is the
    /// next wait's, as it was not with a `ctrl_c()` made anew on every pass.
    #[tokio::test]
    async fn a_signal_that_comes_between_waits_is_kept() {
        let mut signals = StopSignals::new().unwrap();
        for _ in 0..3 {
            // SAFETY: raise only sends this process a signal, which `signals` takes.
            assert_eq!(unsafe { libc::raise(libc::SIGINT) }, 0);
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
            let got = tokio::time::timeout(std::time::Duration::from_secs(30), signals.recv()).await;
            assert!(got.is_ok(), "the signal was lost");
        }
    }
}
