//! Hostile input and faults, as a hostile tester would bring them: implausible poses on the
//! wire while the real odometry flows, a degenerate polygon in a snapshot, a GPU backend
//! without a GPU, snapshots into a read-only directory and onto a full disk, and absurd
//! values for every numeric config key and command-line option. None of them crashes,
//! hangs or blinds the mapper; each is refused (or handled) with a reason.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use polymap::config::Config;
use polymap::map::{Label, MapPolygon, MapSnapshot};
use polymap::ros2::session::{free_loopback_port, loopback_json5};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_polymap")
}

fn straight_320() -> PathBuf {
    root().join("mock_frames/straight_320")
}

/// A mapper's config file: mock camera at `fps` on the bundled stairs, CPU, listening on
/// `port`, with `extra` TOML.
fn mapper_config(dir: &Path, port: u16, fps: u32, extra: &str) -> PathBuf {
    let zenoh = dir.join("mapper.json5");
    std::fs::write(&zenoh, loopback_json5(Some(port), &[])).unwrap();
    let path = dir.join("mapper.toml");
    std::fs::write(
        &path,
        format!(
            "[sources.depth]\nsequence = {:?}\nfps = {fps}\n[pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n{extra}",
            straight_320().display().to_string(),
            zenoh.display().to_string()
        ),
    )
    .unwrap();
    path
}

/// The mock VINS, publishing the bundled stairs' poses to the mapper on `port`.
fn mock_vins(dir: &Path, port: u16, seconds: u32) -> std::process::Child {
    let zenoh = dir.join("vins.json5");
    std::fs::write(&zenoh, loopback_json5(None, &[port])).unwrap();
    let config = dir.join("vins.toml");
    std::fs::write(&config, format!("[zenoh]\nconfig_file = {:?}\n", zenoh.display().to_string())).unwrap();
    Command::new(bin())
        .args([
            "mock-vins",
            straight_320().to_str().unwrap(),
            "--rate",
            "100",
            "--duration",
            &seconds.to_string(),
            "--config",
        ])
        .arg(&config)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// The last status line a mapper printed (its stderr), as numbers by name.
fn last_status(stderr: &str) -> std::collections::HashMap<String, u64> {
    let line = stderr.lines().rev().find(|l| l.contains("frames in ")).unwrap_or_else(|| panic!("no status: {stderr}"));
    let words: Vec<&str> = line
        .split([';', ','])
        .flat_map(|part| {
            let part = part.trim();
            // "<name words> <number>" pieces.
            std::iter::once(part)
        })
        .collect();
    let mut out = std::collections::HashMap::new();
    for part in words {
        let tokens: Vec<&str> = part.split_whitespace().collect();
        let mut name = Vec::new();
        for t in tokens {
            match t.trim_end_matches(')').parse::<u64>() {
                Ok(n) => {
                    out.insert(name.join(" "), n);
                    name.clear();
                }
                Err(_) => name.push(t.trim_start_matches('(').to_string()),
            }
        }
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn implausible_poses_on_the_wire_are_refused_and_the_real_odometry_keeps_mapping() {
    let dir = tempfile::tempdir().unwrap();
    let saved = dir.path().join("map.json");
    let port = free_loopback_port().unwrap();
    let mapper = Command::new(bin())
        .args(["run", "--duration", "14", "--config"])
        .arg(mapper_config(dir.path(), port, 8, &format!("[map]\nsnapshot_path = {:?}\n", saved.display().to_string())))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut vins = mock_vins(dir.path(), port, 16);
    tokio::time::sleep(Duration::from_secs(3)).await;
    // A hostile publisher of its own on /odometry, beside the real VINS.
    use polymap::interface::{Interface, OdometryTopic, convert};
    use polymap::pose::RawPose;
    use polymap::ros2::{Node, NodeOptions, RosName};
    let session = polymap::ros2::session::open(polymap::ros2::session::loopback(None, &[port])).await.unwrap();
    let config = Config::default();
    let node = Node::new(
        &session,
        NodeOptions { namespace: RosName::root(), name: "hostile".into(), ..config.ros2.node_options() },
    )
    .await
    .unwrap();
    let OdometryTopic::Odometry(topic) = Interface::new(&config).odometry else { unreachable!() };
    let publisher = node.publisher(&topic).await.unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let id = [0.0, 0.0, 0.0, 1.0];
    let year_2038 = 2_147_483_647u64 * 1_000_000_000;
    let mut sent = 0;
    for round in 0..20 {
        let now = polymap::clock::now_ns();
        let s = (0.6f64).sqrt();
        for raw in [
            RawPose { stamp_ns: now, position: [1e308, 0.0, 0.0], quat_xyzw: id },
            RawPose { stamp_ns: now, position: [0.0, 1e150, 0.0], quat_xyzw: id },
            RawPose { stamp_ns: now, position: [0.5, 0.0, 0.5], quat_xyzw: [s, s, 0.0, 0.0] },
            RawPose { stamp_ns: now, position: [0.5, 0.0, 0.5], quat_xyzw: [1e200, 0.0, 0.0, 0.0] },
            RawPose { stamp_ns: year_2038, position: [0.5, 0.0, 0.5], quat_xyzw: id },
            RawPose { stamp_ns: now + 30_000_000_000, position: [0.5, 0.0, 0.5], quat_xyzw: id },
        ] {
            publisher.put(&convert::odometry(&raw, "world", "body")).await.unwrap();
            sent += 1;
        }
        if round == 10 {
            // One plausible pose 9 km away, stamped ahead of the odometry: the frames after it
            // would be posed by the propagated poses through it.
            let phantom = RawPose { stamp_ns: now + 400_000_000, position: [9000.0, 0.0, 1.0], quat_xyzw: id };
            publisher.put(&convert::odometry(&phantom, "world", "body")).await.unwrap();
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let out = tokio::task::spawn_blocking(move || mapper.wait_with_output()).await.unwrap().unwrap();
    let _ = vins.kill();
    let _ = vins.wait();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let status = last_status(&stderr);
    let refused = status["refused"];
    assert!(refused >= sent, "{sent} implausible poses sent, {refused} refused: {status:?}");
    // Mapping went on: the poses from 2038 and from 30 s ahead did not become the newest.
    let processed_after = status["processed"];
    let summary = String::from_utf8_lossy(&out.stdout);
    assert!(processed_after >= 30, "{status:?}\n{summary}");
    assert!(stderr.contains("beyond the 10000 m") && stderr.contains("ahead of this machine's clock"), "{stderr}");
    // Nothing of the phantom in the map: every polygon near the stair.
    let map: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&saved).unwrap()).unwrap();
    let polygons = map["polygons"].as_array().unwrap();
    assert!(polygons.len() >= 5, "{}", polygons.len());
    for p in polygons {
        let c = &p["centroid"];
        assert!(c[0].as_f64().unwrap().abs() < 50.0 && c[1].as_f64().unwrap().abs() < 50.0, "a polygon at {c}");
    }
}

fn snapshot_with(boundary: Vec<[f64; 3]>) -> MapSnapshot {
    MapSnapshot {
        version: 0,
        frame: polymap::map::MapFrame::World,
        drift_z: 0.0,
        drift_var: 0.0,
        drift_xy: [0.0; 2],
        drift_yaw: 0.0,
        drift_covariance: None,
        stair: None,
        polygons: vec![MapPolygon {
            id: 1,
            label: Label::Tread,
            normal: [0.0, 0.0, 1.0],
            offset: 0.0,
            area: 1.0,
            centroid: [0.0; 3],
            boundary,
            holes: vec![],
            convex_pieces: vec![],
            insets: vec![],
            observations: 3,
            step: Some(1),
            plane_covariance: [0.0; 16],
            footing: polymap::extract::Footing::Steppable,
            pixels: 0,
        }],
    }
}

#[test]
fn a_degenerate_polygon_in_a_snapshot_is_refused_as_corrupt_and_loading_ends() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("map.json");
    let mut config = Config::default();
    config.map.snapshot_path = path.clone();
    config.map.load_at_start = true;
    // A bowtie whose lobes cancel: no area, so no plane frame to hold it (it used to put the
    // frame's origin near 1e16 m, and the clearing samples' loop never ended).
    let bowtie = vec![[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    std::fs::write(&path, serde_json::to_vec(&snapshot_with(bowtie)).unwrap()).unwrap();
    let map = load_or_hang(&config.map);
    assert!(map.is_empty(), "the corrupt map is not loaded");
    let aside: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(aside.iter().any(|n| n.to_string_lossy().starts_with("map.json.corrupt-")), "moved aside: {aside:?}");
    // A sliver 200 km long and a hundredth of a millimetre wide is a surface, if an odd one:
    // it loads, and quickly.
    let sliver = vec![[0.0, 0.0, 0.0], [2e5, 0.0, 0.0], [2e5, 1e-5, 0.0], [0.0, 1e-5, 0.0]];
    std::fs::write(&path, serde_json::to_vec(&snapshot_with(sliver)).unwrap()).unwrap();
    let map = load_or_hang(&config.map);
    assert_eq!(map.len(), 1);
}

/// `initial_map` of `config`, failing the test if it never returns (a minute is a hang:
/// a load takes milliseconds).
fn load_or_hang(config: &polymap::config::MapConfig) -> polymap::map::PolygonMap {
    let (tx, rx) = std::sync::mpsc::channel();
    let config = config.clone();
    std::thread::spawn(move || tx.send(polymap::map::persist::initial_map(&config)));
    rx.recv_timeout(Duration::from_secs(60)).expect("loading the snapshot never ended")
}

#[test]
fn a_gpu_backend_without_a_gpu_stops_start_up_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let config = mapper_config(dir.path(), port, 30, "");
    std::fs::write(
        &config,
        std::fs::read_to_string(&config).unwrap().replace("backend = \"cpu\"", "backend = \"gpu\""),
    )
    .unwrap();
    let started = Instant::now();
    // No Vulkan driver to be found: the loader looks only where there is none.
    let out = Command::new(bin())
        .args(["run", "--duration", "600", "--config"])
        .arg(&config)
        .env("VK_ICD_FILENAMES", "/nonexistent/polymap-no-icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/polymap-no-icd.json")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    // Far short of the 600 s it would have run: it stopped at start-up.
    assert!(started.elapsed() < Duration::from_secs(300), "it stopped at the end, not at start-up");
    assert!(stderr.contains("the extractor could not start") && stderr.contains("no Vulkan adapter"), "{stderr}");
}

/// `polymap run` as a user that cannot write into a directory root owns (root ignores
/// permissions, so as root the mapper runs as nobody), with the snapshot there.
fn run_mapper(mut cmd: Command, dir: &Path, as_nobody: bool) -> Output {
    if as_nobody {
        let mut perms = std::fs::metadata(dir).unwrap().permissions();
        std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
        std::fs::set_permissions(dir, perms).unwrap();
        let program = cmd.get_program().to_owned();
        let args: Vec<_> = cmd.get_args().map(|a| a.to_owned()).collect();
        let envs: Vec<_> = cmd.get_envs().filter_map(|(k, v)| Some((k.to_owned(), v?.to_owned()))).collect();
        cmd = Command::new("setpriv");
        cmd.args(["--reuid=65534", "--regid=65534", "--clear-groups", "--"]).arg(program).args(args).envs(envs);
    }
    cmd.output().unwrap()
}

#[test]
fn snapshots_that_cannot_be_written_are_counted_and_retried_and_leave_no_partial_file() {
    let root_user = unsafe { libc::geteuid() } == 0;
    // A read-only directory.
    let dir = tempfile::tempdir().unwrap();
    let locked = dir.path().join("locked");
    std::fs::create_dir(&locked).unwrap();
    let mut perms = std::fs::metadata(&locked).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o555);
    std::fs::set_permissions(&locked, perms).unwrap();
    let port = free_loopback_port().unwrap();
    let extra = format!(
        "[map]\nsnapshot_path = {:?}\nsnapshot_period_s = 0.5\n",
        locked.join("map.json").display().to_string()
    );
    let config = mapper_config(dir.path(), port, 8, &extra);
    let mut vins = mock_vins(dir.path(), port, 12);
    let mut cmd = Command::new(bin());
    cmd.args(["run", "--duration", "8", "--config"]).arg(&config);
    let out = run_mapper(cmd, dir.path(), root_user);
    let _ = vins.kill();
    let _ = vins.wait();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let status = last_status(&stderr);
    assert!(status["snapshots failed"] >= 5, "{status:?}\n{stderr}");
    assert!(status["processed"] >= 20, "the mapper kept mapping: {status:?}");
    assert!(std::fs::read_dir(&locked).unwrap().next().is_none(), "nothing written, not even a temporary file");
    // The map could not be saved at the end either: said, and the exit status says so.
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("saving the map at shutdown"), "{stderr}");

    // A full disk: the file size limit stops each write partway (EFBIG, as ENOSPC would).
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let path = dir.path().join("map.json");
    let extra = format!("[map]\nsnapshot_path = {:?}\nsnapshot_period_s = 0.5\n", path.display().to_string());
    let config = mapper_config(dir.path(), port, 8, &extra);
    let mut vins = mock_vins(dir.path(), port, 12);
    let out = Command::new("prlimit")
        .args(["--fsize=4096", "--"])
        .arg(bin())
        .args(["run", "--duration", "8", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let _ = vins.kill();
    let _ = vins.wait();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let status = last_status(&stderr);
    assert!(status["snapshots failed"] >= 3, "{status:?}\n{stderr}");
    assert!(status["processed"] >= 20, "the mapper kept mapping: {status:?}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.iter().all(|n| !n.to_string_lossy().contains(".tmp.")), "no partial file: {left:?}");
    // What is there is the last snapshot that fitted, whole.
    if path.exists() {
        let saved: MapSnapshot = serde_json::from_slice(&std::fs::read(&path).unwrap()).expect("a whole snapshot");
        assert!(saved.polygons.len() <= 3, "{} polygons fit in 4 kB", saved.polygons.len());
    }
    // A temporary file a crash left is removed at start.
    let stale = dir.path().join(".map.json.tmp.4000000");
    std::fs::write(&stale, b"{\"half a").unwrap();
    let out = Command::new(bin()).args(["run", "--duration", "1", "--config"]).arg(&config).output().unwrap();
    assert!(!stale.exists(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Every numeric leaf of the config (arrays by their first element), as dotted keys.
fn numeric_keys(t: &toml::Table, prefix: &str, out: &mut Vec<(String, bool)>) {
    for (k, v) in t {
        let key = format!("{prefix}{k}");
        match v {
            toml::Value::Table(sub) => numeric_keys(sub, &format!("{key}."), out),
            toml::Value::Integer(_) | toml::Value::Float(_) => out.push((key, false)),
            toml::Value::Array(a) if a.iter().all(|e| e.is_float() || e.is_integer()) => out.push((key, true)),
            _ => {}
        }
    }
}

/// The config text with `key` set to `value` (an array's first element).
fn with(key: &str, value: &str, is_array: bool) -> String {
    let (section, name) = key.rsplit_once('.').unwrap();
    let defaults: toml::Table = toml::from_str(&toml::to_string(&Config::default()).unwrap()).unwrap();
    let mut t = &defaults;
    for part in section.split('.') {
        t = t[part].as_table().unwrap();
    }
    let value = if is_array {
        let rest: Vec<String> = t[name].as_array().unwrap()[1..].iter().map(|v| v.to_string()).collect();
        format!("[{value}, {}]", rest.join(", "))
    } else {
        value.to_string()
    };
    format!("[{section}]\n{name} = {value}\n")
}

#[test]
fn every_numeric_config_key_given_absurd_values_is_refused_or_handled() {
    // A tiny sequence to run accepted configs on: the pipeline and the map see every value.
    let dir = tempfile::tempdir().unwrap();
    let seq_dir = dir.path().join("tiny");
    let opts = polymap::synth::SynthOptions { width: 64, frames: 2, ..Default::default() };
    polymap::synth::generate(&opts, &seq_dir, |_, _| {}).unwrap();
    let seq = polymap::sequence::Sequence::open(&seq_dir).unwrap();
    let defaults: toml::Table = toml::from_str(&toml::to_string(&Config::default()).unwrap()).unwrap();
    let mut keys = Vec::new();
    numeric_keys(&defaults, "", &mut keys);
    // The L515's options are all unset by default: each one too.
    keys.extend(
        polymap::camera::CamOption::L515.iter().map(|o| (format!("sources.depth.options.{}", o.name()), false)),
    );
    assert!(keys.len() >= 50, "{keys:?}");
    let (mut refused, mut handled) = (0, 0);
    for (key, is_array) in &keys {
        for value in ["nan", "inf", "-inf", "0", "-1", "1e308", "-1e308", "1e-300"] {
            let text = with(key, value, *is_array);
            match Config::parse(&text, Path::new("t.toml")) {
                Err(e) => {
                    assert!(e.key.starts_with(key.rsplit_once('.').unwrap().0), "{key} = {value}: named {e}");
                    refused += 1;
                }
                Ok(mut c) => {
                    // Handled: the parts that use it run with it.
                    c.pipeline.backend = polymap::config::Backend::Cpu;
                    let mut map = polymap::map::persist::initial_map(&c.map);
                    polymap::replay::replay(&seq, &c, &mut map, |_, _, _| {})
                        .unwrap_or_else(|e| panic!("{key} = {value}: {e}"));
                    let mut poses =
                        polymap::pose::PoseBuffer::with_limits(10, polymap::pose::PoseLimits::from_config(&c.poses));
                    let _ = poses.push(&polymap::pose::RawPose::from(&seq.poses[0]));
                    for hz in
                        [c.sources.depth.fps, c.sources.d435i.ir_fps, c.sources.d435i.gyro_hz, c.sources.d435i.accel_hz]
                    {
                        let _ = Duration::from_secs_f64(1.0 / hz as f64);
                    }
                    let _ = Duration::from_secs_f64(c.map.snapshot_period_s);
                    handled += 1;
                }
            }
        }
    }
    eprintln!("{} keys x 8 values: {refused} refused, {handled} handled", keys.len());
    assert!(refused > handled, "most of these values are absurd for every key");
}

#[test]
fn every_numeric_command_line_option_given_absurd_values_is_refused_or_handled() {
    let dir = tempfile::tempdir().unwrap();
    let seq = straight_320();
    let seq = seq.to_str().unwrap();
    let out = dir.path().join("out");
    let out = out.to_str().unwrap();
    let config = mapper_config(dir.path(), free_loopback_port().unwrap(), 30, "");
    let config = config.to_str().unwrap();
    // Each command with one option left to fill ({}); the rest keeps it quick.
    let commands: &[&[&str]] = &[
        &["synth", out, "--frames", "1", "--width", "{}"],
        &["synth", out, "--frames", "{}", "--width", "32"],
        &["synth", out, "--frames", "1", "--width", "32", "--noise", "{}"],
        &["synth", out, "--frames", "1", "--width", "32", "--drift", "{}"],
        &["synth", out, "--frames", "1", "--width", "32", "--seed", "{}"],
        &["synth", out, "--frames", "1", "--width", "32", "--fps", "{}"],
        &["extract", seq, "--frame", "{}", "--backend", "cpu", "--out", out],
        &["bench", seq, "--frames", "{}", "--backend", "cpu"],
        &["bench", seq, "--frames", "1", "--backend", "cpu", "--threads", "{}"],
        &["run", "--duration", "{}", "--config", config],
        &["demo", "--duration", "{}", "--config", config, "--out", out],
        &["demo", "--duration", "0.001", "--vins-rate", "{}", "--config", config, "--out", out],
        &["demo", "--duration", "0.001", "--vins-latency-ms", "{}", "--config", config, "--out", out],
        &["demo", "--duration", "0.001", "--vins-jitter-ms", "{}", "--config", config, "--out", out],
        &["mock-vins", seq, "--duration", "{}", "--config", config],
        &["mock-vins", seq, "--duration", "0.01", "--rate", "{}", "--config", config],
        &["mock-vins", seq, "--duration", "0.01", "--drift", "{}", "--config", config],
        &["mock-vins", seq, "--duration", "0.01", "--latency-ms", "{}", "--config", config],
        &["mock-vins", seq, "--duration", "0.01", "--jitter-ms", "{}", "--config", config],
    ];
    for command in commands {
        for value in ["nan", "inf", "-inf", "0", "-1", "1e308", "-1e308", "1e-300"] {
            let args: Vec<&str> = command.iter().map(|a| if *a == "{}" { value } else { a }).collect();
            let run = Command::new(bin()).args(&args).stdin(Stdio::null()).output().unwrap();
            let code = run.status.code();
            // clap refuses what is not a number of the option's type (2); polymap refuses
            // what it cannot use (1); 0 is a value it handled. Never a panic (101) or a signal.
            assert!(
                matches!(code, Some(0..=2)),
                "polymap {}: exit {code:?}\n{}",
                args.join(" "),
                String::from_utf8_lossy(&run.stderr)
            );
            if code == Some(1) {
                let stderr = String::from_utf8_lossy(&run.stderr);
                assert!(stderr.starts_with("error: ") || stderr.contains("\nerror: "), "a reason: {stderr}");
            }
        }
    }
}

#[test]
fn polymap_config_checks_the_files_a_config_names() {
    let dir = tempfile::tempdir().unwrap();
    let check = |extra: &str| {
        let path = dir.path().join("c.toml");
        std::fs::write(&path, extra).unwrap();
        let out = Command::new(bin()).arg("config").arg(&path).current_dir(root()).output().unwrap();
        (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    assert_eq!(check("").0, Some(0), "the defaults, from the repository");
    let bad_zenoh = dir.path().join("bad.json5");
    std::fs::write(&bad_zenoh, "{ mode: \"peer\", listen: { endpoints: [\"tcp/nowhere\"] }, oops }").unwrap();
    let (code, err) = check(&format!("[zenoh]\nconfig_file = {:?}\n", bad_zenoh.display().to_string()));
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("zenoh.config_file"), "{err}");
    let (code, err) = check(&format!("[map]\nsnapshot_path = {:?}\n", dir.path().display().to_string()));
    assert_eq!(code, Some(1));
    assert!(err.contains("map.snapshot_path") && err.contains("is a directory"), "{err}");
    let (code, err) = check("[sources.depth]\nsequence = \"/nonexistent/stairs\"\n");
    assert_eq!(code, Some(1));
    assert!(err.contains("sources.depth.sequence") && err.contains("/nonexistent/stairs"), "{err}");
    // /dev/zero as the config is refused, not read until memory runs out.
    let out = Command::new(bin()).args(["config", "/dev/zero"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a regular file"));
}

#[test]
fn a_map_kilometres_long_and_a_metre_wide_is_drawn() {
    // A phantom's polygons 9 km out beside the stair: the picture is one pixel high, not none.
    let long = snapshot_with(vec![[0.0, 0.0, 0.0], [9000.0, 0.0, 0.0], [9000.0, 0.05, 0.0], [0.0, 0.05, 0.0]]);
    let img = polymap::map::render::top_down(&long, None);
    assert!(img.width() >= 100 && img.height() >= 1, "{}x{}", img.width(), img.height());
    let dir = tempfile::tempdir().unwrap();
    img.save(dir.path().join("map.png")).unwrap();
}
