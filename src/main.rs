//! The polymap command line: a thin layer over the library.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use polymap::cli::{self, progress};
use polymap::config::{Backend, Config};
use polymap::logs::{Log, LogKind, LogTopics};
use polymap::mock::vins::MockVinsOptions;
use polymap::sequence::Sequence;
use polymap::synth::path::Direction;
use polymap::synth::{self, JumpOptions, SceneKind, SynthOptions};

#[derive(Parser)]
#[command(name = "polymap", version, about = "Real-time polygonal terrain mapping for legged robots", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write a synthetic stair sequence (ray-cast L515-like depth, poses, truth, labels)
    Synth {
        /// Output sequence directory (created)
        out: PathBuf,
        #[arg(long, value_enum, default_value = "straight")]
        scene: SceneKind,
        /// Up the flight of steps or down it
        #[arg(long, value_enum, default_value = "up")]
        walk: Direction,
        /// Image width in pixels; height is 3/4 of it
        #[arg(long, default_value_t = 320)]
        width: u32,
        #[arg(long, default_value_t = 30)]
        frames: usize,
        /// Range noise at 1 m, mm (0 = noise-free: no noise, mixed pixels or dropouts)
        #[arg(long, default_value_t = 2.0)]
        noise: f64,
        /// Vertical drift added to the written poses, mm per frame
        #[arg(long, default_value_t = 0.0)]
        drift: f64,
        /// Horizontal drift added to the written poses, mm per frame in x and y
        #[arg(long, num_args = 2, value_names = ["X", "Y"], allow_negative_numbers = true)]
        drift_xy: Option<Vec<f64>>,
        /// Yaw drift added to the written poses (about the walk's start), degrees per frame
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        drift_yaw: f64,
        /// A step of the written poses from frame K on (a loop closure): x, y, z in mm, yaw in degrees
        #[arg(long, num_args = 5, value_names = ["K", "X", "Y", "Z", "YAW"], allow_negative_numbers = true)]
        jump: Option<Vec<f64>>,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Frame rate of the stamps, Hz
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// Also write colour pictures of depth and labels to OUT/preview/
        #[arg(long)]
        preview: bool,
    },
    /// Check a sequence and summarise it (--preview writes colour pictures of its frames), or
    /// say what a log (FILE.bag, FILE.mcap, a rosbag2 directory) holds and what of it replays
    Inspect {
        seq: PathBuf,
        #[command(flatten)]
        topics: LogTopicArgs,
        /// Directory for one picture per frame: depth in colour, and truth labels if present
        #[arg(long)]
        preview: Option<PathBuf>,
    },
    /// Extract one frame's planar polygons as JSON (camera frame, or world with --world)
    Extract {
        seq: PathBuf,
        #[arg(long, default_value_t = 0)]
        frame: usize,
        /// Write the JSON here instead of to stdout
        #[arg(long)]
        out: Option<PathBuf>,
        /// Transform the polygons to the world frame with the frame's pose from poses.txt
        #[arg(long)]
        world: bool,
        /// Write a picture of every stage into this directory
        #[arg(long)]
        debug: Option<PathBuf>,
        /// Pipeline settings from this config file (default: the built-in defaults)
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override the config's pipeline.backend
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Single-frame accuracy over every frame of a sequence with truth: alpha, IOU, step-height error
    Eval {
        seq: PathBuf,
        /// Pipeline settings from this config file (default: the built-in defaults)
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print the per-tread scores and the summary as JSON instead of a table
        #[arg(long)]
        json: bool,
        /// Override the config's pipeline.backend
        #[arg(long, value_enum)]
        backend: Option<Backend>,
        /// Write one picture per frame (with --map: per tread, top-down) of how polygons and
        /// treads overlap (green: both, red: polygon only, blue: tread only)
        #[arg(long)]
        debug: Option<PathBuf>,
        /// Score this map (from `polymap replay --out`) against the truth instead of single frames
        #[arg(long)]
        map: Option<PathBuf>,
        /// Score each frame's polygons against per-pixel plane truth (labels.png, planes.txt:
        /// ../shared/real/abw) with Hoover et al.'s metric; SEQ may be a folder of such sequences
        #[arg(long, conflicts_with = "map")]
        segmentation: bool,
        /// With --segmentation: the overlap a correct detection needs, of both (Hoover's T)
        #[arg(long, default_value_t = 0.8)]
        tolerance: f64,
    },
    /// Time extraction per stage over many frames (looping the sequence): median, p99, fps
    Bench {
        seq: PathBuf,
        #[arg(long, value_enum)]
        backend: Option<Backend>,
        /// Frames to time (the sequence is looped); at least 300 for a p99 worth reading
        #[arg(long, default_value_t = 300)]
        frames: usize,
        /// Pipeline settings from this config file (default: the built-in defaults)
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print the numbers as JSON
        #[arg(long)]
        json: bool,
        /// Threads for the CPU stages (default: RAYON_NUM_THREADS, else one per core)
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Map a whole sequence, or a robot's log: a ROS 1 bag (FILE.bag) or a ROS 2 bag in MCAP
    /// (FILE.mcap or a rosbag2 directory) with depth images, their camera_info and odometry
    Replay {
        seq: PathBuf,
        #[command(flatten)]
        topics: LogTopicArgs,
        /// Write the map's JSON here
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write a top-down picture of the map here (with the truth's tread outlines, if known)
        #[arg(long)]
        render: Option<PathBuf>,
        /// Turn the drift filter off (to see what it buys)
        #[arg(long)]
        no_drift_filter: bool,
        /// Write the drift estimate after every frame (against the injected drift, where the
        /// sequence's truth has it) to STEM.csv and its plot to STEM.png
        #[arg(long, value_name = "STEM")]
        drift_trace: Option<PathBuf>,
        /// Settings from this config file (default: the built-in defaults); its [map]
        /// snapshot settings apply: load at start, save on the period and at the end
        #[arg(long)]
        config: Option<PathBuf>,
        /// Override the config's pipeline.backend
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// The live mapper: depth source -> extraction -> map, poses in and polygons out over Zenoh
    Run {
        /// Settings (default: the built-in defaults: the mock camera on the bundled stairs)
        #[arg(long)]
        config: Option<PathBuf>,
        /// Stop after this many seconds (default: until SIGINT / SIGTERM)
        #[arg(long)]
        duration: Option<f64>,
    },
    /// The live mapper (as `run`), recording every frame it maps with the pose it used, as a
    /// sequence in OUT that `polymap replay OUT` maps to the same map (OUT/map.json, the live
    /// session's); ends at --duration, at a limit, or at SIGINT / SIGTERM
    Record {
        out: PathBuf,
        /// Settings (default: the built-in defaults: the mock camera on the bundled stairs)
        #[arg(long)]
        config: Option<PathBuf>,
        /// Stop after this many seconds
        #[arg(long)]
        duration: Option<f64>,
        /// Stop after this many frames
        #[arg(long)]
        max_frames: Option<u64>,
        /// Stop once the depth images take this many megabytes
        #[arg(long)]
        max_mb: Option<f64>,
    },
    /// The whole loop on one machine: mock camera + mock VINS + mapper over Zenoh on
    /// loopback, printing live status; then the final map and its picture
    Demo {
        /// Seconds to run
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Settings (default: the built-in defaults: the bundled mock stairs)
        #[arg(long)]
        config: Option<PathBuf>,
        /// Where the final map goes
        #[arg(long, default_value = "out/map.json")]
        out: PathBuf,
        /// Where its top-down picture goes
        #[arg(long, default_value = "out/map.png")]
        render: PathBuf,
        /// Mock VINS poses per second (VINS-Fusion on a robot: 10-20)
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.rate_hz)]
        vins_rate: f64,
        /// How late the mock VINS publishes each pose after its stamp, ms
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.latency_ms)]
        vins_latency_ms: f64,
        /// Jitter of the mock VINS's stamps and delays, ms
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.jitter_ms)]
        vins_jitter_ms: f64,
        /// The mock VINS's IMU-rate propagated poses per second (imu_propagate); 0: none
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.propagate_hz)]
        vins_propagate_hz: f64,
        /// The mock VINS drifts as a visual-inertial odometry does: x, y, z in mm per second,
        /// yaw in degrees per second (for example 10 10 5 0.05)
        #[arg(long, num_args = 4, value_names = ["X", "Y", "Z", "YAW"], allow_negative_numbers = true)]
        vins_drift: Option<Vec<f64>>,
        /// Also on ROS 1: the mapper and the mock VINS register with the rosmaster
        /// ROS_MASTER_URI names (start one with `roscore`), VINS's poses go over ROS 1
        #[arg(long)]
        ros1: bool,
    },
    /// Publish a sequence's poses as VINS-Fusion would: nav_msgs/Odometry on the config's
    /// odometry topic (ROS 2's, or ROS 1's with --ros1), the sequence looped on the wall clock
    MockVins {
        seq: PathBuf,
        /// Poses per second (VINS-Fusion on a robot: 10-20)
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.rate_hz)]
        rate: f64,
        /// How late each pose is published after its stamp, ms
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.latency_ms)]
        latency_ms: f64,
        /// Jitter of the stamps and of the delays, ms
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.jitter_ms)]
        jitter_ms: f64,
        /// IMU-rate propagated poses per second on the config's ros2.imu_propagate; 0: none
        #[arg(long, default_value_t = MockVinsOptions::ROBOT.propagate_hz)]
        propagate_hz: f64,
        /// Vertical drift added to the poses, mm per second
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        drift: f64,
        /// Horizontal drift added to the poses, mm per second in x and y
        #[arg(long, num_args = 2, value_names = ["X", "Y"], allow_negative_numbers = true)]
        drift_xy: Option<Vec<f64>>,
        /// Yaw drift added to the poses (about VINS's origin), degrees per second
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        drift_yaw: f64,
        /// Stop after this many seconds (default: run until interrupted)
        #[arg(long)]
        duration: Option<f64>,
        /// Zenoh and ROS settings ([zenoh], [ros2], [ros1]) from this config file
        #[arg(long)]
        config: Option<PathBuf>,
        /// Publish on ROS 1 (the rosmaster ROS_MASTER_URI names), as VINS-Fusion's original
        #[arg(long)]
        ros1: bool,
    },
    /// A Zenoh router in a process of its own (as rmw_zenohd), with the given Zenoh config
    /// (e.g. config/zenoh/robot/router.json5: mutual TLS and access control)
    Router {
        /// Zenoh JSON5 config file (its mode is set to router)
        #[arg(long)]
        config: PathBuf,
        /// Stop after this many seconds (default: until SIGINT / SIGTERM)
        #[arg(long)]
        duration: Option<f64>,
    },
    /// Check a config file and print it with every default filled in
    Config { file: PathBuf },
}

fn main() {
    polymap::keep_freed_memory();
    polymap::files::survive_file_size_limits();
    let cli = Cli::parse();
    let terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    // On a terminal, a recording's progress line stands for the 1 Hz status lines.
    let level = if terminal && matches!(cli.command, Command::Record { .. }) { "warn" } else { "info" };
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| level.into()))
        .with_writer(std::io::stderr)
        // Colours for a terminal only, not for journald or a log file.
        .with_ansi(terminal)
        .init();
    if let Err(e) = run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Synth {
            out,
            scene,
            walk,
            width,
            frames,
            noise,
            drift,
            drift_xy,
            drift_yaw,
            jump,
            seed,
            fps,
            preview,
        } => {
            let jump = jump.map(|j| match j.as_slice() {
                &[k, x, y, z, yaw] if k >= 0.0 && k.fract() == 0.0 => {
                    Ok(JumpOptions { frame: k as usize, xyz_mm: [x, y, z], yaw_deg: yaw })
                }
                _ => Err(anyhow::anyhow!("--jump {j:?}: the frame K must be a whole number from 0")),
            });
            let opts = SynthOptions {
                scene,
                walk,
                width,
                frames,
                noise_mm: noise,
                drift_mm_per_frame: drift,
                drift_xy_mm_per_frame: drift_xy.map_or([0.0; 2], |v| [v[0], v[1]]),
                drift_yaw_deg_per_frame: drift_yaw,
                jump: jump.transpose()?,
                seed,
                fps,
            };
            if let Some(p) = opts.problem() {
                bail!("{p}");
            }
            let bar = progress(frames as u64, "synth");
            synth::generate(&opts, &out, |_, _| bar.inc(1)).with_context(|| format!("writing {}", out.display()))?;
            bar.finish_and_clear();
            let seq = Sequence::open(&out).context("reading back what was written")?;
            println!(
                "{}: {} frames {}x{} of the {:?} scene",
                out.display(),
                seq.len(),
                seq.intrinsics.width,
                seq.intrinsics.height,
                scene
            );
            if preview {
                cli::inspect::write_previews(&seq, &out.join("preview"))?;
            }
        }
        Command::Inspect { seq, topics, preview } => {
            if let Some(log) = Log::find(&seq)? {
                if preview.is_some() {
                    bail!("--preview: for sequences; replay the log with --render to see its map");
                }
                return cli::inspect::summarise_log(&log, &topics.of(log.kind));
            }
            let s = Sequence::open(&seq)?;
            cli::inspect::summarise(&s)?;
            if let Some(dir) = preview {
                cli::inspect::write_previews(&s, &dir)?;
            }
        }
        Command::Extract { seq, frame, out, world, debug, config, backend } => {
            let config = load_config(config, backend)?;
            cli::extract::extract_frame(&seq, frame, &config, world, debug.as_deref(), out.as_deref())?;
        }
        Command::Eval { seq, config, json, backend, debug, segmentation: true, tolerance, .. } => {
            if !(tolerance > 0.5 && tolerance <= 1.0) {
                bail!("--tolerance {tolerance}: Hoover's tolerance lies in (0.5, 1]");
            }
            let config = load_config(config, backend)?;
            cli::eval::evaluate_segmentation(&seq, &config, tolerance, json, debug.as_deref())?;
        }
        Command::Eval { seq, config, json, backend, debug, map: Some(map), .. } => {
            if config.is_some() || backend.is_some() {
                bail!("--map scores a finished map: --config and --backend do not apply");
            }
            cli::eval::evaluate_map(&Sequence::open(&seq)?, &map, json, debug.as_deref())?;
        }
        Command::Eval { seq, config, json, backend, debug, map: None, .. } => {
            let config = load_config(config, backend)?;
            cli::eval::evaluate(&Sequence::open(&seq)?, &config, json, debug.as_deref())?;
        }
        Command::Replay { seq, topics, out, render, no_drift_filter, drift_trace, config, backend } => {
            let mut config = load_config(config, backend)?;
            if no_drift_filter {
                config.map.drift_filter = false;
            }
            let (out, render, trace) = (out.as_deref(), render.as_deref(), drift_trace.as_deref());
            cli::replay::replay(&seq, |kind| topics.of(kind), &config, out, render, trace)?;
        }
        Command::Bench { seq, backend, frames, config, json, threads } => {
            if let Some(n) = threads {
                if !(1..=1024).contains(&n) {
                    bail!("--threads {n}: give 1 to 1024");
                }
                rayon::ThreadPoolBuilder::new().num_threads(n).build_global().context("setting up the thread pool")?;
            }
            let config = load_config(config, backend)?;
            cli::bench::bench(&Sequence::open(&seq)?, &config, frames, json)?;
        }
        Command::Run { config, duration } => {
            let config = load_config(config, None)?;
            let duration = duration.map(seconds).transpose()?;
            let runtime = tokio::runtime::Runtime::new()?;
            println!("{}", runtime.block_on(polymap::runtime::run(&config, duration))?);
        }
        Command::Record { out, config, duration, max_frames, max_mb } => {
            let config = load_config(config, None)?;
            let duration = duration.map(seconds).transpose()?;
            let max_bytes = match max_mb {
                Some(mb) if !(mb.is_finite() && mb > 0.0) => bail!("--max-mb {mb}: give a positive size"),
                Some(mb) => Some((mb * 1e6) as u64),
                None => None,
            };
            if max_frames == Some(0) {
                bail!("--max-frames 0: give at least one frame");
            }
            let options = polymap::runtime::record::RecordOptions { dir: out.clone(), max_frames, max_bytes };
            let runtime = tokio::runtime::Runtime::new()?;
            let (report, recorded) = runtime.block_on(polymap::runtime::run_recording(&config, duration, options))?;
            println!("{report}");
            println!(
                "recorded {} frames ({:.1} MB) into {}; `polymap replay {}` maps them again",
                recorded.frames,
                recorded.bytes as f64 / 1e6,
                out.display(),
                out.display()
            );
        }
        Command::Demo {
            duration,
            config,
            out,
            render,
            vins_rate,
            vins_latency_ms,
            vins_jitter_ms,
            vins_propagate_hz,
            vins_drift,
            ros1,
        } => {
            let mut config = load_config(config, None)?;
            config.ros1.enabled |= ros1;
            let duration = seconds(duration)?;
            config.map.snapshot_path = out.clone();
            let runtime = tokio::runtime::Runtime::new()?;
            let s = runtime.block_on(polymap::runtime::demo::demo(
                &config,
                duration,
                MockVinsOptions {
                    rate_hz: vins_rate,
                    latency_ms: vins_latency_ms,
                    jitter_ms: vins_jitter_ms,
                    propagate_hz: vins_propagate_hz,
                    drift_mm_per_s: vins_drift.as_ref().map_or(0.0, |d| d[2]),
                    drift_xy_mm_per_s: vins_drift.as_ref().map_or([0.0; 2], |d| [d[0], d[1]]),
                    drift_yaw_deg_per_s: vins_drift.as_ref().map_or(0.0, |d| d[3]),
                    ..MockVinsOptions::ROBOT
                },
            ))?;
            println!("{s} in {}", out.display());
            let map: polymap::map::MapSnapshot = serde_json::from_str(&std::fs::read_to_string(&out)?)?;
            let seq = Sequence::open(&config.sources.depth.sequence)?;
            if let Some(dir) = render.parent() {
                std::fs::create_dir_all(dir)?;
            }
            polymap::map::render::top_down(&map, seq.truth.as_ref())
                .save(&render)
                .with_context(|| format!("writing {}", render.display()))?;
            println!("picture in {}", render.display());
        }
        Command::MockVins {
            seq,
            rate,
            latency_ms,
            jitter_ms,
            propagate_hz,
            drift,
            drift_xy,
            drift_yaw,
            duration,
            config,
            ros1,
        } => {
            let mut config = load_config(config, None)?;
            config.ros1.enabled |= ros1;
            let s = Sequence::open(&seq)?;
            let opts = MockVinsOptions {
                rate_hz: rate,
                latency_ms,
                jitter_ms,
                propagate_hz,
                drift_mm_per_s: drift,
                drift_xy_mm_per_s: drift_xy.map_or([0.0; 2], |v| [v[0], v[1]]),
                drift_yaw_deg_per_s: drift_yaw,
                duration: duration.map(seconds).transpose()?,
            };
            if let Some(p) = opts.problem() {
                bail!("{p}");
            }
            let runtime = tokio::runtime::Runtime::new()?;
            let sent = runtime.block_on(async {
                tokio::select! {
                    r = polymap::mock::vins::run(&s, &config, opts) => r,
                    _ = tokio::signal::ctrl_c() => Ok(0),
                }
            })?;
            tracing::info!("mock VINS: {sent} poses published");
        }
        Command::Router { config, duration } => {
            let duration = duration.map(seconds).transpose()?;
            tokio::runtime::Runtime::new()?.block_on(polymap::runtime::router::run(&config, duration))?;
        }
        Command::Config { file } => {
            let config = Config::load(&file)?;
            config.check_files().map_err(|(key, reason)| polymap::config::ConfigError {
                file: file.clone(),
                key,
                reason,
            })?;
            print!("{}", toml::to_string(&config)?);
        }
    }
    Ok(())
}

/// A `--duration` in seconds: from a millisecond to three years.
fn seconds(s: f64) -> Result<std::time::Duration> {
    if !(s.is_finite() && (1e-3..=1e8).contains(&s)) {
        bail!("--duration {s} must be within 0.001..=100000000 seconds");
    }
    Ok(std::time::Duration::from_secs_f64(s))
}

/// The config file's settings (or the defaults), with the backend overridden if asked.
fn load_config(file: Option<PathBuf>, backend: Option<Backend>) -> Result<Config> {
    let mut config = match file {
        Some(f) => Config::load(f)?,
        None => Config::default(),
    };
    if let Some(b) = backend {
        config.pipeline.backend = b;
    }
    Ok(config)
}

/// A log's topics; each defaults to what logs of its kind use (`polymap::logs::LogTopics::defaults`).
#[derive(clap::Args)]
struct LogTopicArgs {
    /// A log's depth images (sensor_msgs/Image: 16UC1 in mm, or sources.depth.image_unit_m;
    /// 32FC1 in m) [default: /l515/depth/image_rect_raw in a ROS 1 bag,
    /// /camera/camera/depth/image_rect_raw in MCAP]
    #[arg(long)]
    depth_topic: Option<String>,
    /// Their camera_info [default: the depth topic's namespace's camera_info]
    #[arg(long)]
    camera_info_topic: Option<String>,
    /// The odometry (nav_msgs/Odometry or geometry_msgs/PoseStamped): each image's pose,
    /// interpolated at its stamp [default: /vins_estimator/odometry in a ROS 1 bag, /odometry in MCAP]
    #[arg(long)]
    odometry_topic: Option<String>,
}

impl LogTopicArgs {
    fn of(&self, kind: LogKind) -> LogTopics {
        let d = LogTopics::defaults(kind);
        LogTopics {
            depth: self.depth_topic.clone().unwrap_or(d.depth),
            camera_info: match (&self.camera_info_topic, &self.depth_topic) {
                (Some(info), _) => info.clone(),
                (None, Some(depth)) => match depth.rsplit_once('/') {
                    Some((namespace, _)) => format!("{namespace}/camera_info"),
                    None => "camera_info".into(),
                },
                (None, None) => d.camera_info,
            },
            odometry: self.odometry_topic.clone().unwrap_or(d.odometry),
        }
    }
}
