//! `polymap run`: the live mapper.
//!
//! ```text
//! depth source (tokio task) ─► latest-frame slot ─► extractor thread (GPU/CPU work, pose
//!   lookup, map update) ─► bounded channel ─► publisher task (Zenoh)
//! Zenoh pose subscriber ─► pose buffer    queryables: map, foothold    status: 1 Hz    markers
//! ```
//! When extraction falls behind, the newest frame wins: a frame still waiting when the
//! next arrives is dropped and counted. A frame with no odometry pose within the gap is
//! skipped and counted. SIGINT / SIGTERM (or `--duration`) stop it; the map is saved.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::config::{Config, DepthSourceKind};
use crate::extract::Extractor;
use crate::map::{MapSnapshot, PolygonMap};
use crate::mock_vins::{SequenceClock, now_ns};
use crate::pose::{NoPose, PoseBuffer};
use crate::ros::{self, FootholdMsg, FramePolygonsMsg, Header, MapMsg, MapUpdateMsg, PolygonMsg, StatusMsg, Time};
use crate::sequence::Sequence;
use crate::types::{DepthFrame, Intrinsics};

/// The newest frame, waiting for the extractor; a newer one replaces it.
struct Latest {
    frame: Mutex<Option<(DepthFrame, Intrinsics)>>,
    ready: Condvar,
}

impl Latest {
    /// Puts a frame in; true when it replaced one that was never taken.
    fn put(&self, f: (DepthFrame, Intrinsics)) -> bool {
        let replaced = self.frame.lock().expect("slot lock").replace(f).is_some();
        self.ready.notify_one();
        replaced
    }

    /// The waiting frame, after at most `wait`.
    fn take(&self, wait: Duration) -> Option<(DepthFrame, Intrinsics)> {
        let guard = self.frame.lock().expect("slot lock");
        let (mut guard, _) = self.ready.wait_timeout_while(guard, wait, |f| f.is_none()).expect("slot lock");
        guard.take()
    }
}

/// Counters shared by the tasks.
#[derive(Default)]
struct Counters {
    frames_in: AtomicU64,
    processed: AtomicU64,
    dropped: AtomicU64,
    without_pose: AtomicU64,
}

impl Counters {
    /// A camera's new frame into the slot, counting it and the one it may replace.
    fn offer(&self, slot: &Latest, frame: (DepthFrame, Intrinsics)) {
        self.frames_in.fetch_add(1, Ordering::Relaxed);
        if slot.put(frame) {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// What the extractor thread hands the publisher.
struct Outgoing {
    stamp_ns: u64,
    frame: FramePolygonsMsg,
    update: MapUpdateMsg,
}

/// What `run` did, for the caller's last words.
#[derive(Clone, Debug)]
pub struct RunSummary {
    pub frames_in: u64,
    pub processed: u64,
    pub dropped: u64,
    pub without_pose: u64,
    pub map_polygons: usize,
    /// Frame stamp to published, over the whole run, ms.
    pub latency: crate::bench::Spread,
}

/// The keys polymap publishes and answers on, under `<key_prefix>/<robot>/`.
pub struct Keys {
    pub frame_polygons: String,
    pub map_updates: String,
    pub map: String,
    pub foothold: String,
    pub status: String,
    pub markers: String,
}

impl std::fmt::Display for RunSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} frames in, {} processed, {} dropped, {} without pose; frame-to-published latency median {:.1} ms, p99 {:.1} ms; map of {} polygons",
            self.frames_in,
            self.processed,
            self.dropped,
            self.without_pose,
            self.latency.median,
            self.latency.p99,
            self.map_polygons
        )
    }
}

impl Keys {
    pub fn new(config: &Config) -> Keys {
        let p = format!("{}/{}", config.zenoh.key_prefix, config.zenoh.robot);
        Keys {
            frame_polygons: format!("{p}/frame/polygons"),
            map_updates: format!("{p}/map/updates"),
            map: format!("{p}/map"),
            foothold: format!("{p}/foothold"),
            status: format!("{p}/status"),
            markers: format!("{p}/markers"),
        }
    }
}

/// Runs until SIGINT / SIGTERM or `duration`; saves the map at the end.
pub async fn run(config: &Config, duration: Option<Duration>) -> Result<RunSummary> {
    let source = &config.sources.depth;
    let seq = match source.kind {
        DepthSourceKind::Mock => Some(Sequence::open(&source.sequence)?),
        DepthSourceKind::Realsense | DepthSourceKind::Bag => None,
        DepthSourceKind::Sequence => {
            bail!(
                "sources.depth.kind = \"sequence\" is for offline work (polymap replay); live needs mock, realsense or bag"
            )
        }
    };
    let session = crate::bus::open_session(&config.zenoh).await?;
    let keys = Keys::new(config);
    let encoding = config.zenoh.encoding;
    let gap_ns = (config.zenoh.pose_max_gap_s * 1e9) as u64;
    let poses = Arc::new(Mutex::new(PoseBuffer::new(4096, gap_ns)));
    let _pose_sub = crate::bus::subscribe_poses(&session, &config.zenoh.pose_key, poses.clone()).await?;
    let map = Arc::new(Mutex::new(crate::replay::initial_map(config)));
    let counters = Arc::new(Counters::default());
    let stop = Arc::new(AtomicBool::new(false));
    let slot = Arc::new(Latest { frame: Mutex::new(None), ready: Condvar::new() });
    let (out_tx, mut out_rx) = tokio::sync::mpsc::channel::<Outgoing>(8);

    // Extraction, pose lookup and map update on their own thread: CPU/GPU work off the runtime.
    let worker = {
        let (slot, stop, poses, map, counters) =
            (slot.clone(), stop.clone(), poses.clone(), map.clone(), counters.clone());
        let config = config.clone();
        let body_camera = extrinsic(&config);
        std::thread::Builder::new().name("extractor".into()).spawn(move || -> Result<()> {
            let mut extractor = Extractor::new(&config.pipeline)?;
            while !stop.load(Ordering::Relaxed) {
                let Some((frame, intrinsics)) = slot.take(Duration::from_millis(100)) else { continue };
                let (polys, stages, _) = match extractor.extract(&frame, &intrinsics) {
                    Ok(r) => r,
                    Err(e) => {
                        tracing::warn!("frame at {} ns: {e}", frame.stamp_ns);
                        continue;
                    }
                };
                let Some(world_body) = pose_at(&poses, frame.stamp_ns, gap_ns, &stop) else {
                    counters.without_pose.fetch_add(1, Ordering::Relaxed);
                    continue;
                };
                let t_world_camera = world_body * body_camera;
                let mut m = map.lock().expect("map lock");
                let update = m.update(&polys.polygons, &t_world_camera, &intrinsics, Some(&stages.depth));
                let header = Header { stamp: Time::from_ns(frame.stamp_ns), frame_id: "world".into() };
                let corrected = m.corrected(&t_world_camera);
                let frame_msg = FramePolygonsMsg {
                    header: header.clone(),
                    polygons: polys.polygons.iter().map(|p| PolygonMsg::of_frame(&p.transformed(&corrected))).collect(),
                };
                let content = |ids: &[u64], m: &mut PolygonMap| -> Vec<PolygonMsg> {
                    ids.iter().filter_map(|id| m.polygon(*id)).map(|p| PolygonMsg::of_map(&p)).collect()
                };
                let update_msg = MapUpdateMsg {
                    header,
                    added: content(&update.added, &mut m),
                    changed: content(&update.changed, &mut m),
                    removed: update.removed.clone(),
                    drift_z: m.drift.z,
                    drift_var: m.drift.var,
                };
                drop(m);
                counters.processed.fetch_add(1, Ordering::Relaxed);
                if out_tx
                    .blocking_send(Outgoing { stamp_ns: frame.stamp_ns, frame: frame_msg, update: update_msg })
                    .is_err()
                {
                    break;
                }
            }
            Ok(())
        })?
    };

    let camera = match &seq {
        Some(seq) => mock_camera(seq, source.fps, slot.clone(), stop.clone(), counters.clone())?,
        None => realsense_camera(source, slot.clone(), stop.clone(), counters.clone()).await?,
    };
    let d435i = stream_d435i(config, seq.as_ref(), &session, stop.clone()).await?;

    // Queryables: the whole map, and the foothold under a point.
    let map_q = {
        let map = map.clone();
        session
            .declare_queryable(keys.map.clone())
            .callback(move |query| {
                let snap = map.lock().expect("map lock").snapshot();
                let reply = ros::encode_as(&map_msg(&snap), encoding);
                let key = query.key_expr().clone();
                tokio::spawn(async move {
                    if let Err(e) = query.reply(key, reply).await {
                        tracing::warn!("map reply: {e}");
                    }
                });
            })
            .await
            .map_err(|e| anyhow!("declaring {}: {e}", keys.map))?
    };
    let foothold_q = {
        let map = map.clone();
        session
            .declare_queryable(keys.foothold.clone())
            .callback(move |query| {
                let params = query.parameters();
                let coord = |k: &str| params.get(k).and_then(|v| v.parse::<f64>().ok()).filter(|v| v.is_finite());
                let key = query.key_expr().clone();
                let answer = match (coord("x"), coord("y"), coord("z")) {
                    (Some(x), Some(y), Some(z)) => {
                        let snap = map.lock().expect("map lock").snapshot();
                        Ok(ros::encode_as(&foothold(&snap, [x, y, z]), encoding))
                    }
                    _ => Err(format!("{} needs finite x, y and z parameters, got {params:?}", key.as_str())),
                };
                tokio::spawn(async move {
                    let sent = match answer {
                        Ok(bytes) => query.reply(key, bytes).await,
                        Err(why) => query.reply_err(why).await,
                    };
                    if let Err(e) = sent {
                        tracing::warn!("foothold reply: {e}");
                    }
                });
            })
            .await
            .map_err(|e| anyhow!("declaring {}: {e}", keys.foothold))?
    };

    let started = Instant::now();
    let mut latencies: Vec<f64> = Vec::new();
    let mut all_latencies: Vec<f64> = Vec::new();
    let mut status_tick = tokio::time::interval(Duration::from_secs(1));
    let mut snapshot_tick = tokio::time::interval(Duration::from_secs_f64(config.map.snapshot_period_s));
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let deadline = async {
        match duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::pin!(deadline);
    loop {
        tokio::select! {
            Some(out) = out_rx.recv() => {
                session.put(keys.frame_polygons.clone(), ros::encode_as(&out.frame, encoding)).await.map_err(|e| anyhow!("publishing: {e}"))?;
                session.put(keys.map_updates.clone(), ros::encode_as(&out.update, encoding)).await.map_err(|e| anyhow!("publishing: {e}"))?;
                session.put(keys.markers.clone(), ros::encode_as(&ros::markers(&out.update), encoding)).await.map_err(|e| anyhow!("publishing: {e}"))?;
                latencies.push(now_ns().saturating_sub(out.stamp_ns) as f64 * 1e-6);
            }
            _ = status_tick.tick() => {
                let status = status_msg(&counters, &poses, &map, &latencies);
                all_latencies.append(&mut latencies);
                tracing::info!(
                    "frames in {} processed {} dropped {} without pose {}; latency median {:.1} ms p99 {:.1} ms; poses {} (refused {}); drift {:.1} mm; map {} polygons",
                    status.frames_in, status.frames_processed, status.frames_dropped, status.frames_without_pose,
                    status.latency_median_ms, status.latency_p99_ms, status.poses_accepted, status.poses_refused,
                    status.drift_z * 1e3, status.map_polygons
                );
                session.put(keys.status.clone(), ros::encode_as(&status, encoding)).await.map_err(|e| anyhow!("publishing: {e}"))?;
            }
            _ = snapshot_tick.tick(), if started.elapsed() > Duration::from_millis(500) => {
                let mut m = map.lock().expect("map lock");
                crate::replay::save_snapshot(&mut m, config)?;
            }
            _ = &mut deadline => break,
            _ = tokio::signal::ctrl_c() => break,
            _ = sigterm.recv() => break,
        }
    }
    stop.store(true, Ordering::Relaxed);
    camera.abort();
    if let Some(d435i) = d435i {
        d435i.abort();
    }
    drop(out_rx);
    worker.join().map_err(|_| anyhow!("the extractor thread panicked"))??;
    drop((map_q, foothold_q));
    all_latencies.append(&mut latencies);
    let mut m = map.lock().expect("map lock");
    crate::replay::save_snapshot(&mut m, config).context("saving the map at shutdown")?;
    Ok(RunSummary {
        frames_in: counters.frames_in.load(Ordering::Relaxed),
        processed: counters.processed.load(Ordering::Relaxed),
        dropped: counters.dropped.load(Ordering::Relaxed),
        without_pose: counters.without_pose.load(Ordering::Relaxed),
        map_polygons: m.len(),
        latency: crate::bench::spread(&all_latencies),
    })
}

/// The odometry pose at a frame's stamp, waiting up to one gap for it to arrive.
fn pose_at(poses: &Mutex<PoseBuffer>, stamp_ns: u64, gap_ns: u64, stop: &AtomicBool) -> Option<Isometry3<f64>> {
    let waited = Instant::now();
    loop {
        let found = poses.lock().expect("pose lock").at(stamp_ns);
        match found {
            Ok(t) => return Some(t),
            Err(NoPose::NotYet { .. }) | Err(NoPose::Empty)
                if waited.elapsed() < Duration::from_nanos(gap_ns) && !stop.load(Ordering::Relaxed) =>
            {
                std::thread::sleep(Duration::from_millis(2));
            }
            Err(e) => {
                tracing::debug!("frame skipped: {e}");
                return None;
            }
        }
    }
}

/// T_body_camera from the config.
fn extrinsic(config: &Config) -> Isometry3<f64> {
    let e = &config.sources.extrinsics;
    let [x, y, z, w] = e.quat_xyzw;
    Isometry3::from_parts(
        Translation3::from(Vector3::from(e.xyz)),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    )
}

fn status_msg(counters: &Counters, poses: &Mutex<PoseBuffer>, map: &Mutex<PolygonMap>, latencies: &[f64]) -> StatusMsg {
    let p = poses.lock().expect("pose lock").counters;
    let m = map.lock().expect("map lock");
    let spread = crate::bench::spread(latencies);
    StatusMsg {
        header: Header { stamp: Time::from_ns(now_ns()), frame_id: "world".into() },
        frames_in: counters.frames_in.load(Ordering::Relaxed),
        frames_processed: counters.processed.load(Ordering::Relaxed),
        frames_dropped: counters.dropped.load(Ordering::Relaxed),
        frames_without_pose: counters.without_pose.load(Ordering::Relaxed),
        latency_median_ms: spread.median,
        latency_p99_ms: spread.p99,
        poses_accepted: p.accepted,
        poses_refused: p.rejected + p.undecodable,
        drift_z: m.drift.z,
        map_polygons: m.len() as u32,
    }
}

pub fn map_msg(s: &MapSnapshot) -> MapMsg {
    MapMsg {
        header: Header { stamp: Time::from_ns(now_ns()), frame_id: "world".into() },
        drift_z: s.drift_z,
        drift_var: s.drift_var,
        polygons: s.polygons.iter().map(PolygonMsg::of_map).collect(),
    }
}

/// The convex piece under `p` (seen from above, on a surface within 0.3 m of its height),
/// or failing that the nearest such piece.
pub fn foothold(s: &MapSnapshot, p: [f64; 3]) -> FootholdMsg {
    let mut best: Option<(f64, f64, &crate::map::MapPolygon, &Vec<[f64; 3]>)> = None;
    for poly in s.polygons.iter().filter(|q| q.label.is_horizontal() && q.normal[2].abs() > 1e-3) {
        let z = -(poly.normal[0] * p[0] + poly.normal[1] * p[1] + poly.offset) / poly.normal[2];
        let dz = (z - p[2]).abs();
        if dz > 0.3 {
            continue;
        }
        for piece in &poly.convex_pieces {
            let d = distance_xy(piece, [p[0], p[1]]);
            let better = best.is_none_or(|(bd, bdz, _, _)| (d, dz) < (bd, bdz) && (d < bd || (d == 0.0 && dz < bdz)));
            if better {
                best = Some((d, dz, poly, piece));
            }
        }
    }
    let header = Header { stamp: Time::from_ns(now_ns()), frame_id: "world".into() };
    match best {
        None => FootholdMsg { header, ..FootholdMsg::default() },
        Some((d, _, poly, piece)) => FootholdMsg {
            header,
            found: true,
            contains: d == 0.0,
            polygon_id: poly.id,
            label: PolygonMsg::of_map(poly).label,
            normal: poly.normal,
            offset: poly.offset,
            piece: piece.iter().map(ros::point).collect(),
            distance: d,
        },
    }
}

/// Horizontal distance from `q` to a convex ring (0 inside).
fn distance_xy(ring: &[[f64; 3]], q: [f64; 2]) -> f64 {
    let n = ring.len();
    let mut inside = n >= 3;
    let mut nearest = f64::INFINITY;
    let area: f64 = (0..n).map(|i| ring[i][0] * ring[(i + 1) % n][1] - ring[(i + 1) % n][0] * ring[i][1]).sum();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        let cross = (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]);
        if cross * area.signum() < 0.0 {
            inside = false;
        }
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = (dx * dx + dy * dy).max(1e-300);
        let t = (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2).clamp(0.0, 1.0);
        nearest = nearest.min((a[0] + t * dx - q[0]).hypot(a[1] + t * dy - q[1]));
    }
    if inside { 0.0 } else { nearest }
}

/// A TCP port on 127.0.0.1 that nothing listens on now.
pub fn free_loopback_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// A Zenoh peer on loopback only, multicast scouting off: listening on `listen` (a port)
/// and connecting to `connect`.
pub fn loopback_json5(listen: Option<u16>, connect: Option<u16>) -> String {
    let listen = listen.map_or("tcp/127.0.0.1:0".to_string(), |p| format!("tcp/127.0.0.1:{p}"));
    let connect = connect.map_or(String::new(), |p| format!("\"tcp/127.0.0.1:{p}\""));
    format!(
        r#"{{ mode: "peer", listen: {{ endpoints: ["{listen}"] }}, connect: {{ endpoints: [{connect}] }}, scouting: {{ multicast: {{ enabled: false }} }} }}"#
    )
}

/// The whole loop on one machine: the mock VINS and the mapper as two Zenoh peers on
/// loopback, for `duration`; the map is saved where `config.map.snapshot_path` says.
pub async fn demo(config: &Config, duration: Duration, vins_rate_hz: f64) -> Result<RunSummary> {
    let port = free_loopback_port()?;
    let dir = std::env::temp_dir().join(format!("polymap-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let write = |name: &str, text: String| -> Result<std::path::PathBuf> {
        let path = dir.join(name);
        std::fs::write(&path, text)?;
        Ok(path)
    };
    let mut mapper = config.clone();
    mapper.zenoh.config_file = write("mapper.json5", loopback_json5(Some(port), None))?;
    let mut vins = config.zenoh.clone();
    vins.config_file = write("vins.json5", loopback_json5(None, Some(port)))?;
    let seq = Sequence::open(&config.sources.depth.sequence)?;
    let opts = crate::mock_vins::MockVinsOptions { rate_hz: vins_rate_hz, drift_mm_per_s: 0.0, duration: None };
    let vins_task = tokio::spawn(async move { crate::mock_vins::run(&seq, &vins, opts).await });
    let summary = run(&mapper, Some(duration)).await;
    vins_task.abort();
    if let Ok(Err(e)) = vins_task.await {
        tracing::error!("mock VINS: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    summary
}

/// The mock camera: the sequence looped on the wall clock, like the mock VINS.
fn mock_camera(
    seq: &Sequence,
    fps: u32,
    slot: Arc<Latest>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
) -> Result<tokio::task::JoinHandle<()>> {
    let clock = SequenceClock::new(seq)?;
    let stamps: Vec<u64> = seq.poses.iter().map(|p| p.stamp_ns).collect();
    let frames: Vec<DepthFrame> = (0..seq.len()).map(|k| seq.depth(k)).collect::<Result<_, _>>()?;
    let intrinsics = seq.intrinsics;
    Ok(tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / fps as f64));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        while !stop.load(Ordering::Relaxed) {
            tick.tick().await;
            // Like a camera, deliver a frame when the loop shows it, stamped then: a
            // frame is not held back until the next tick of an unrelated timer.
            let now = now_ns();
            let (shown, k) = clock.next_frame(now, &stamps);
            tokio::time::sleep(Duration::from_nanos(shown.saturating_sub(now))).await;
            let mut frame = frames[k].clone();
            frame.stamp_ns = shown;
            counters.offer(&slot, (frame, intrinsics));
        }
    }))
}

/// The L515 (or a bag) on a thread of its own. Opened here, so a missing camera stops
/// start-up with an error naming it; later failures reconnect with backoff.
#[cfg(feature = "realsense")]
async fn realsense_camera(
    source: &crate::config::DepthSourceConfig,
    slot: Arc<Latest>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
) -> Result<tokio::task::JoinHandle<()>> {
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
            counters.offer(&slot, frame);
            !stop.load(Ordering::Relaxed)
        });
        tracing::info!("depth camera stopped: {} frames, {} reconnects", stats.frames, stats.reconnects);
    }))
}

/// Reopening a camera that stopped: first after 250 ms, doubling up to 5 s.
#[cfg(feature = "realsense")]
const BACKOFF: (Duration, Duration) = (Duration::from_millis(250), Duration::from_secs(5));

#[cfg(not(feature = "realsense"))]
async fn realsense_camera(
    source: &crate::config::DepthSourceConfig,
    _: Arc<Latest>,
    _: Arc<AtomicBool>,
    _: Arc<Counters>,
) -> Result<tokio::task::JoinHandle<()>> {
    bail!("sources.depth.kind = {:?} needs polymap built with --features realsense", source.kind)
}

/// The D435i's IR and IMU out over Zenoh for VINS: the mock along the mock camera's
/// sequence, or the real camera with its emitter off. None when `sources.d435i.kind = none`.
async fn stream_d435i(
    config: &Config,
    seq: Option<&Sequence>,
    session: &zenoh::Session,
    stop: Arc<AtomicBool>,
) -> Result<Option<tokio::task::JoinHandle<()>>> {
    use crate::camera::mock_d435i::MockD435i;
    use crate::config::D435iKind;
    let cfg = config.sources.d435i.clone();
    let (tx, rx) = tokio::sync::mpsc::channel(64);
    match cfg.kind {
        D435iKind::None => return Ok(None),
        D435iKind::Mock => {
            let seq =
                seq.ok_or_else(|| anyhow!("sources.d435i.kind = \"mock\" needs the mock depth camera's sequence"))?;
            let mock =
                MockD435i::from_sequence(seq, &extrinsic(config), &cfg).map_err(|e| anyhow!("mock D435i: {e}"))?;
            let clock = SequenceClock::new(seq)?;
            let cfg = cfg.clone();
            tokio::spawn(async move { mock.run(clock, &cfg, tx).await });
        }
        D435iKind::Realsense => real_d435i(&cfg, tx, stop).await?,
    }
    let session = session.clone();
    Ok(Some(tokio::spawn(async move {
        if let Err(e) = crate::bus::publish_d435i(&session, &cfg, rx).await {
            tracing::warn!("D435i publishing stopped: {e}");
        }
    })))
}

/// The real D435i on its own thread: opened (emitter off, verified) before start-up goes
/// on; a stream that stops is reopened with backoff.
#[cfg(feature = "realsense")]
async fn real_d435i(
    cfg: &crate::config::D435iConfig,
    tx: tokio::sync::mpsc::Sender<crate::camera::D435iSample>,
    stop: Arc<AtomicBool>,
) -> Result<()> {
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
    _: tokio::sync::mpsc::Sender<crate::camera::D435iSample>,
    _: Arc<AtomicBool>,
) -> Result<()> {
    bail!("sources.d435i.kind = \"realsense\" needs polymap built with --features realsense")
}
