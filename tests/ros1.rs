//! polymap as the robot's ROS 1 nodes see it, against a real ROS 1: Debian's ros_comm
//! (Noetic's 1.15): `roscore`, rospy, rostopic, rosnode, rosservice, and genmsg/genpy, which
//! generate polymap_msgs for rospy from polymap's own package. Nothing here shares code with
//! polymap but the test's own bookkeeping: the peer is tests/peer/ros1_peer.py on rospy.
//!
//! scripts/test.sh installs the Debian packages.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use polymap::ros2::session::{free_loopback_port, loopback_json5};

/// Debian's python, where rospy is.
const PYTHON: &str = "/usr/bin/python3";

mod common;

use common::root;

/// A `roscore` on a port of its own, stopped (SIGINT, as a user would) when dropped.
struct Roscore {
    child: Child,
    uri: String,
    dir: tempfile::TempDir,
}

impl Roscore {
    fn start() -> Roscore {
        let dir = tempfile::tempdir().unwrap();
        let port = free_loopback_port().unwrap();
        let uri = format!("http://127.0.0.1:{port}/");
        let log = std::fs::File::create(dir.path().join("roscore.log")).unwrap();
        let child = Command::new("roscore")
            .args(["-p", &port.to_string()])
            .env("ROS_MASTER_URI", &uri)
            .env("ROS_HOME", dir.path())
            .env("ROS_HOSTNAME", "127.0.0.1")
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .expect("roscore (scripts/test.sh installs Debian's ros-core)");
        let core = Roscore { child, uri, dir };
        let deadline = Instant::now() + Duration::from_secs(30);
        while core.command("rosnode", &["list"]).map(|o| !o.contains("/rosout")).unwrap_or(true) {
            assert!(Instant::now() < deadline, "roscore did not come up: {}", core.log());
            std::thread::sleep(Duration::from_millis(300));
        }
        core
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("roscore.log")).unwrap_or_default()
    }

    /// The environment a ROS 1 user has: the master, this machine, polymap_msgs for rospy.
    fn env(&self, cmd: &mut Command) {
        cmd.env("ROS_MASTER_URI", &self.uri)
            .env("ROS_HOSTNAME", "127.0.0.1")
            .env("ROS_HOME", self.dir.path())
            .env("PYTHONPATH", python_messages());
    }

    /// A ROS 1 command line tool's output, or its failure.
    fn command(&self, tool: &str, args: &[&str]) -> Result<String, String> {
        let mut cmd = Command::new(tool);
        cmd.args(args);
        self.env(&mut cmd);
        let out = cmd.output().map_err(|e| format!("{tool}: {e}"))?;
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        match out.status.success() {
            true => Ok(text),
            false => Err(format!("{tool} {args:?}: {text}{}", String::from_utf8_lossy(&out.stderr))),
        }
    }
}

impl Drop for Roscore {
    fn drop(&mut self) {
        // SIGINT: roslaunch stops rosmaster and rosout with it.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// polymap_msgs as a robot builds it (its catkin package, `catkin_make` in a workspace of
/// its own), and the terrain packages polymap sends as genpy generates them from their
/// Noetic definitions (polymap carries those): the PYTHONPATH rospy finds them on. Made once.
fn python_messages() -> String {
    static MADE: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    MADE.get_or_init(|| {
        let out = std::env::temp_dir().join(format!("polymap-ros1-{}", std::process::id()));
        let src = out.join("ws/src");
        std::fs::create_dir_all(&src).unwrap();
        std::os::unix::fs::symlink(root().join("polymap_msgs"), src.join("polymap_msgs")).unwrap();
        // -C: catkin_make takes its workspace from $PWD otherwise, not from the directory it runs in.
        let built = Command::new("catkin_make")
            .arg("-C")
            .arg(out.join("ws"))
            .arg(format!("-DPYTHON_EXECUTABLE={PYTHON}"))
            .current_dir(out.join("ws"))
            .env("ROS_VERSION", "1")
            .output()
            .expect("catkin_make (scripts/test.sh installs Debian's catkin)");
        let said = format!("{}{}", String::from_utf8_lossy(&built.stdout), String::from_utf8_lossy(&built.stderr));
        assert!(built.status.success() && out.join("ws/devel").exists(), "catkin_make polymap_msgs: {said}");

        let defs = root().join("src/ros1/definitions");
        let py = out.join("py");
        for package in ["grid_map_msgs", "convex_plane_decomposition_msgs"] {
            let includes = [
                format!("-I{package}:{}", defs.join(package).display()),
                format!("-Igrid_map_msgs:{}", defs.join("grid_map_msgs").display()),
                "-Istd_msgs:/usr/share/std_msgs/msg".into(),
                "-Igeometry_msgs:/usr/share/geometry_msgs/msg".into(),
            ];
            let target = py.join(package).join("msg");
            for file in std::fs::read_dir(defs.join(package)).unwrap().map(|e| e.unwrap().path()) {
                let status = Command::new(PYTHON)
                    .args(["/usr/lib/genpy/genmsg_py.py", "-p", package, "-o"])
                    .arg(&target)
                    .args(&includes)
                    .arg(&file)
                    .status()
                    .expect("genpy (scripts/test.sh installs python3-genpy)");
                assert!(status.success(), "genpy on {}", file.display());
            }
            let status = Command::new(PYTHON)
                .args(["/usr/lib/genpy/genmsg_py.py", "--initpy", "-p", package, "-o"])
                .arg(&target)
                .status()
                .unwrap();
            assert!(status.success(), "genpy --initpy for {package}");
            std::fs::write(py.join(package).join("__init__.py"), "").unwrap();
        }
        format!("{}:{}", out.join("ws/devel/lib/python3/dist-packages").display(), py.display())
    })
    .clone()
}

/// The mapper's sources: the bundled mock stairs at 8 Hz and the mock D435i.
fn mock_sources() -> String {
    format!(
        "[sources.depth]\nsequence = {:?}\nfps = 8\n[sources.d435i]\nkind = \"mock\"\nir_width = 320\nir_height = 240\n",
        root().join("mock_frames/straight_320").display().to_string()
    )
}

/// `polymap run` with `[ros1] enabled`, `sources` (TOML), the CPU twin, ROS 2 on a Zenoh
/// port of its own; its log in `dir/mapper.log`.
fn mapper(core: &Roscore, dir: &Path, seconds: u32, sources: &str, zenoh_port: u16) -> Child {
    let zenoh = dir.join("mapper.json5");
    std::fs::write(&zenoh, loopback_json5(Some(zenoh_port), &[])).unwrap();
    let config = dir.join("mapper.toml");
    std::fs::write(
        &config,
        format!(
            "{sources}[pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n[ros1]\nenabled = true\n",
            zenoh.display().to_string(),
        ),
    )
    .unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_polymap"));
    cmd.args(["run", "--duration", &seconds.to_string(), "--config"])
        .arg(&config)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("mapper.log")).unwrap());
    core.env(&mut cmd);
    cmd.spawn().unwrap()
}

/// [`mapper`] on `sources` for a minute, once the master lists it; and its log.
fn registered_mapper(core: &Roscore, dir: &Path, sources: &str) -> (Child, std::path::PathBuf) {
    let polymap = mapper(core, dir, 60, sources, free_loopback_port().unwrap());
    let log = dir.join("mapper.log");
    wait_for_node(core, "/polymap", &log);
    (polymap, log)
}

/// Waits until the master lists `node`.
fn wait_for_node(core: &Roscore, node: &str, log: &Path) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while !core.command("rosnode", &["list"]).unwrap_or_default().lines().any(|l| l.trim() == node) {
        assert!(
            Instant::now() < deadline,
            "{node} never registered: {}",
            std::fs::read_to_string(log).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(300));
    }
}

#[test]
fn a_rospy_node_receives_every_topic_feeds_odometry_and_calls_the_services() {
    let core = Roscore::start();
    let dir = tempfile::tempdir().unwrap();
    let (mut polymap, log) = registered_mapper(&core, dir.path(), &mock_sources());

    // What a ROS 1 user sees of the node.
    let topics = core.command("rostopic", &["list"]).unwrap();
    for t in [
        "/polygon_new_markers",
        "/polymap/frame_polygons",
        "/polymap/map_updates",
        "/polymap/map",
        "/polymap/markers",
        "/polymap/status",
        "/tf",
        "/convex_plane_decomposition_ros/planar_terrain",
        "/camera/infra1/image_rect_raw",
        "/camera/infra1/camera_info",
        "/camera/infra2/image_rect_raw",
        "/camera/imu",
    ] {
        assert!(topics.lines().any(|l| l.trim() == t), "rostopic list lacks {t}:\n{topics}");
    }
    let info = core.command("rosnode", &["info", "/polymap"]).unwrap();
    for expected in [
        "/polygon_new_markers [visualization_msgs/MarkerArray]",
        "/polymap/map [polymap_msgs/Map]",
        "/vins_estimator/odometry",
        "/polymap/get_map",
        "/polymap/get_foothold",
    ] {
        assert!(info.contains(expected), "rosnode info /polymap lacks {expected:?}:\n{info}");
    }
    let service_type = core.command("rosservice", &["type", "/polymap/get_foothold"]).unwrap();
    assert_eq!(service_type.trim(), "polymap_msgs/GetFoothold");

    let mut peer = Command::new(PYTHON);
    peer.arg(root().join("tests/peer/ros1_peer.py"))
        .args(["--seconds", "14", "--sequence"])
        .arg(root().join("mock_frames/straight_320"));
    core.env(&mut peer);
    let out = peer.output().unwrap();
    // rosservice call, as a user types it, while polymap still runs.
    let foothold = core.command("rosservice", &["call", "/polymap/get_foothold", "point: {x: 0.42, y: 0.0, z: 0.30}"]);
    let whole_map = core.command("rosservice", &["call", "/polymap/get_map"]);
    let status_echo = core.command("rostopic", &["echo", "-n", "1", "/polymap/status"]);
    stop(&mut polymap);
    let log_text = std::fs::read_to_string(&log).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer failed: {stdout}\n{}\n{log_text}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    eprintln!("{}", serde_json::to_string_pretty(&v).unwrap());

    // The paper authors' topic as the vendor's stair planner reads it (README "ROS 1",
    // tests/peer/ros1_peer.py): closed LINE_STRIPs in the robot's odom frame, whose z = 0 is the
    // soles (here the mock world's floor: the default origin), level treads only, each as
    // four corners and the closing point.
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root().join("mock_frames/straight_320/truth.json")).unwrap())
            .unwrap();
    let (rise, steps_in_stair) = (truth["stair"]["rise"].as_f64().unwrap(), truth["stair"]["steps"].as_i64().unwrap());
    let strips = v["polygon_new_markers"].as_array().unwrap();
    assert!(strips.len() >= 20, "{} strips on /polygon_new_markers", strips.len());
    for s in strips {
        assert_eq!(s["type"], 4, "LINE_STRIP: {s}");
        assert_eq!(s["ns"], "polygons_new");
        assert_eq!(s["frame"], "odom");
        assert_eq!(s["closed"], true, "a closed outline: {s}");
        assert_eq!(s["points"], 5, "four corners and the closing point: {s}");
        assert!(s["z_spread"].as_f64().unwrap() < 0.02, "no riser or wall: {s}");
        assert!((s["lifetime"].as_f64().unwrap() - 0.5).abs() < 1e-9);
        assert_eq!(s["w"], 1.0);
    }
    // Each array as the planner walks it, in message order: every tread it keeps within 5 mm
    // of a tread of the truth, none refused by its chain, no floor, and a staircase wherever
    // it keeps two or more.
    let readings = v["planner_readings"].as_array().unwrap();
    let mut chained = std::collections::BTreeSet::new();
    let (mut worst_mm, mut staircases) = (0.0f64, 0);
    for r in readings {
        let skipped = &r["skipped"];
        for why in ["few_points", "at_the_soles", "off_the_chain"] {
            assert_eq!(skipped[why], 0, "{why}: {r}");
        }
        let steps = r["steps"].as_array().unwrap();
        for step in steps {
            let z = step["z"].as_f64().unwrap();
            let k = (z / rise).round() as i64;
            assert!((1..=steps_in_stair).contains(&k), "a step at z {z:.3} on no tread: {r}");
            worst_mm = worst_mm.max((z - k as f64 * rise).abs() * 1e3);
            chained.insert(k);
        }
        if steps.len() >= 2 {
            assert_eq!(r["staircase"], true, "a staircase: {r}");
            staircases += 1;
        }
    }
    eprintln!(
        "planner: {} arrays, {staircases} staircases, treads {chained:?}, worst height {worst_mm:.1} mm",
        readings.len()
    );
    assert!(worst_mm <= 5.0, "a tread {worst_mm:.1} mm off its height");
    assert!(staircases * 2 >= readings.len(), "{staircases} staircases in {} arrays", readings.len());
    // Every tread the camera saw deep enough for the planner (its mapped outline a tread's
    // going front to back) is chained in some array.
    let seen: std::collections::BTreeSet<i64> = (v["get_map"]["tread_extents"].as_array().unwrap().iter())
        .filter(|e| e[1].as_f64().unwrap() >= 0.9 * truth["stair"]["going"].as_f64().unwrap())
        .map(|e| (e[0].as_f64().unwrap() / rise).round() as i64)
        .collect();
    assert!(seen.len() >= 3, "treads seen whole: {seen:?}");
    assert!(seen.is_subset(&chained), "treads seen {seen:?}, chained {chained:?}");

    // Every other topic arrived.
    let counts = &v["counts"];
    for (topic, least) in [
        ("/polymap/frame_polygons", 20),
        ("/polymap/map_updates", 20),
        ("/polymap/status", 5),
        ("/tf", 20),
        ("/camera/infra1/image_rect_raw", 20),
        ("/camera/infra1/camera_info", 20),
        ("/camera/infra2/image_rect_raw", 20),
        ("/camera/infra2/camera_info", 20),
        ("/camera/imu", 500),
        ("/convex_plane_decomposition_ros/planar_terrain", 5),
    ] {
        assert!(counts[topic].as_u64().unwrap() >= least, "{topic}: {} messages, expected {least}+", counts[topic]);
    }
    assert_eq!(v["frame_polygons_frame"], "map");
    assert_eq!(v["tf"]["parent"], "map");
    assert_eq!(v["tf"]["child"], "world");
    assert_eq!(v["image"]["encoding"], "mono8");
    assert_eq!(
        v["image"]["bytes"].as_u64(),
        v["image"]["width"].as_u64().map(|w| w * v["image"]["height"].as_u64().unwrap())
    );
    // infra2's projection carries the baseline, as realsense-ros writes it.
    assert!(v["camera_info2"]["P"][3].as_f64().unwrap() < 0.0, "{}", v["camera_info2"]);
    assert!((v["imu"]["accel_z"].as_f64().unwrap()).abs() > 1.0, "gravity in the IMU: {}", v["imu"]);
    assert!(v["terrain"]["regions"].as_u64().unwrap() >= 3, "{}", v["terrain"]);
    assert_eq!(v["terrain"]["frame"], "map");

    // The odometry from rospy fed the mapper: frames mapped, none without a pose once it
    // flowed, the absurd poses refused.
    let (early, during) = (&v["status_early"], &v["status_during"]);
    assert!(during["processed"].as_u64().unwrap() >= early["processed"].as_u64().unwrap() + 10, "{early} -> {during}");
    assert_eq!(during["without_pose"], early["without_pose"], "no frame without a pose once odometry flowed");
    // The odometry publisher's connection broken off from its side: polymap connects again
    // while the master lists it, and its poses come in again.
    let reconnect = &v["reconnect"];
    assert!(reconnect["broken"].as_u64().unwrap() >= 1, "{reconnect}");
    assert!(
        reconnect["accepted_after"].as_u64().unwrap() >= reconnect["accepted_at_break"].as_u64().unwrap() + 20,
        "poses taken after the publisher broke off: {reconnect}"
    );
    let status = &v["status"];
    assert!(status["processed"].as_u64().unwrap() >= 20, "{status}");
    assert!(status["poses_accepted"].as_u64().unwrap() >= 50, "{status}");
    assert!(status["poses_refused"].as_u64().unwrap() >= 4, "the absurd poses: {status}");
    assert!(log_text.contains("pose on /vins_estimator/odometry refused"), "{log_text}");

    // The latched map and markers reach a subscriber that joins after the map stopped
    // changing, at once.
    assert!(v["late_map"]["polygons"].as_u64().unwrap() >= 5, "{}", v["late_map"]);
    assert!(v["late_map"]["after_s"].as_f64().unwrap() < 1.0, "{}", v["late_map"]);
    assert!(v["late_markers"]["markers"].as_u64().unwrap() >= 5, "{}", v["late_markers"]);
    assert!(v["late_markers"]["after_s"].as_f64().unwrap() < 1.0, "{}", v["late_markers"]);

    // The services, from rospy and from rosservice.
    assert!(v["get_map"]["treads"].as_u64().unwrap() >= 3, "{}", v["get_map"]);
    assert_eq!(v["get_map"]["footing_consistent"], true, "{}", v["get_map"]);
    assert!(v["get_map"]["steppable_treads"].as_u64().unwrap() >= 3, "{}", v["get_map"]);
    assert_eq!(v["get_map"]["frame"], "map");
    assert_eq!(v["get_foothold"]["found"], true, "{}", v["get_foothold"]);
    let whole_map = whole_map.unwrap();
    assert!(whole_map.matches("convex_pieces:").count() >= 5, "rosservice call get_map: {whole_map}");
    let foothold = foothold.unwrap();
    assert!(foothold.contains("found: True"), "rosservice call get_foothold: {foothold}");
    let status_echo = status_echo.unwrap();
    assert!(status_echo.contains("frames_processed:"), "rostopic echo status: {status_echo}");
}

/// SIGINT, as systemd or a user stops it; waits for the map to be saved.
fn stop(child: &mut Child) {
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let deadline = Instant::now() + Duration::from_secs(15);
    while Instant::now() < deadline {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// The MD5 sums polymap computes for every type it has a definition of equal genmsg's: the
/// standard types' as rospy's installed classes carry them, polymap_msgs' and the terrain's
/// as genpy generated them from the .msg files.
#[test]
fn md5_sums_equal_genmsgs_and_rospys() {
    let types: Vec<&str> = polymap::ros1::types::known_types().collect();
    let services = ["polymap_msgs/GetMap", "polymap_msgs/GetFoothold"];
    let script = r#"
import importlib, json, sys
out = {}
for name in sys.argv[1:]:
    pkg, ty = name.split("/")
    kind = "srv" if ty.startswith(("GetMap", "GetFoothold")) else "msg"
    out[name] = getattr(importlib.import_module(f"{pkg}.{kind}"), ty)._md5sum
print(json.dumps(out))
"#;
    let out = Command::new(PYTHON)
        .current_dir(std::env::temp_dir())
        .args(["-c", script])
        .args(&types)
        .args(services)
        .env("PYTHONPATH", python_messages())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let theirs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(types.len() >= 30, "{types:?}");
    for t in &types {
        assert_eq!(polymap::ros1::types::md5_of(t).unwrap(), theirs[t].as_str().unwrap(), "{t}");
    }
    for s in services {
        assert_eq!(polymap::ros1::types::service_md5_of(s).unwrap(), theirs[s].as_str().unwrap(), "{s}");
    }
}

/// The terrain messages' ROS 1 MD5 sums as their upstream packages generate them, pinned: genmsg
/// (Debian's python3-genmsg, `gentools.compute_md5`) on the .msg files of ANYbotics/grid_map
/// (grid_map_msgs/msg, master at 73a5b61) and of leggedrobotics/elevation_mapping_cupy
/// (plane_segmentation/convex_plane_decomposition_msgs/msg, master at 20a8a26), 2026-12-01.
/// GridMap's is the one upstream's generated code carries. A field polymap's copy gets wrong
/// changes polymap's sum (and genpy's of the copy), so it fails here, not only on a robot.
#[test]
fn the_terrain_messages_md5_sums_are_upstream_s() {
    for (ty, upstream) in [
        ("grid_map_msgs/GridMapInfo", "43ee5430e1c253682111cb6bedac0ef9"),
        ("grid_map_msgs/GridMap", "95681e052b1f73bf87b7eb984382b401"),
        ("convex_plane_decomposition_msgs/Point2d", "ff8d7d66dd3e4b731ef14a45d38888b6"),
        ("convex_plane_decomposition_msgs/Polygon2d", "0083ddac30f807eeef29c66ffedb79c7"),
        ("convex_plane_decomposition_msgs/PolygonWithHoles2d", "62e09666eefc245f9ca3347875cb36cc"),
        ("convex_plane_decomposition_msgs/BoundingBox2d", "882c57bd03c558cc1c0ff70ad4c5ef0e"),
        ("convex_plane_decomposition_msgs/PlanarRegion", "8cff8c52c8273f12e2fd17b9d4a3d417"),
        ("convex_plane_decomposition_msgs/PlanarTerrain", "081e702fce247ef5685dd96b39e3dfd4"),
    ] {
        assert_eq!(polymap::ros1::types::md5_of(ty).unwrap(), upstream, "{ty}");
    }
}

/// The master's `[code, message, value]` answer to an XML-RPC call, by hand (no polymap code).
fn master_call(uri: &str, body: &str) -> String {
    let addr = uri.trim_start_matches("http://").trim_end_matches('/');
    let mut s = TcpStream::connect(addr).unwrap();
    write!(s, "POST / HTTP/1.0\r\nContent-Type: text/xml\r\nContent-Length: {}\r\n\r\n{body}", body.len()).unwrap();
    let mut answer = String::new();
    s.read_to_string(&mut answer).unwrap();
    answer
}

/// polymap's TCPROS port and XML-RPC URI, from the master (lookupService, lookupNode).
fn polymap_ports(core: &Roscore) -> (String, String) {
    let call = |method: &str, arg: &str| {
        master_call(
            &core.uri,
            &format!(
                "<?xml version=\"1.0\"?><methodCall><methodName>{method}</methodName><params>\
                 <param><value><string>/test</string></value></param><param><value><string>{arg}</string></value></param>\
                 </params></methodCall>"
            ),
        )
    };
    let between = |text: &str, start: &str| {
        let at = text.find(start).unwrap_or_else(|| panic!("{start} in {text}")) + start.len();
        text[at..].split('<').next().unwrap().to_string()
    };
    let service = call("lookupService", "/polymap/get_map");
    let tcpros = between(&service, "<string>rosrpc://");
    assert!(tcpros.parse::<std::net::SocketAddr>().is_ok(), "a TCPROS address from {service}");
    let node = call("lookupNode", "/polymap");
    let api = format!("http://{}", between(&node, "<string>http://"));
    (tcpros, api)
}

fn resident_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// Raw TCPROS and XML-RPC peers that lie about lengths, stop half-way, send garbage or say
/// nothing: each refused and counted, resident memory flat, and the node serves on.
#[test]
fn hostile_tcpros_and_xmlrpc_peers_are_refused_counted_and_do_not_grow_memory() {
    let core = Roscore::start();
    let dir = tempfile::tempdir().unwrap();
    let (mut polymap, log) = registered_mapper(&core, dir.path(), &mock_sources());
    std::thread::sleep(Duration::from_secs(3));
    let (tcpros, api) = polymap_ports(&core);
    let before = resident_kib(polymap.id());

    let send = |bytes: &[u8], hold: Duration| {
        let mut s = TcpStream::connect(&tcpros).unwrap();
        let _ = s.write_all(bytes);
        std::thread::sleep(hold);
    };
    // A connection header claiming 4 GiB, then more bytes as if it meant it.
    let mut four_gib = 0xFFFF_FFF0u32.to_le_bytes().to_vec();
    four_gib.extend(std::iter::repeat_n(b'x', 64 * 1024));
    send(&four_gib, Duration::from_millis(500));
    // A header cut short: 100 bytes promised, 10 sent, then the peer goes.
    let mut truncated = 100u32.to_le_bytes().to_vec();
    truncated.extend_from_slice(b"topic=/pol");
    send(&truncated, Duration::ZERO);
    // Garbage: a field longer than its header, then noise.
    let mut garbage = 12u32.to_le_bytes().to_vec();
    garbage.extend_from_slice(&0xFFFF_0000u32.to_le_bytes());
    garbage.extend_from_slice(&[0xde, 0xad, 0xbe, 0xef, 1, 2, 3, 4]);
    send(&garbage, Duration::from_millis(100));
    // A subscriber with a valid header, then a frame of 3 GiB on a service connection.
    let header = |fields: &[&str]| {
        let mut body = Vec::new();
        for f in fields {
            body.extend_from_slice(&(f.len() as u32).to_le_bytes());
            body.extend_from_slice(f.as_bytes());
        }
        let mut out = (body.len() as u32).to_le_bytes().to_vec();
        out.extend(body);
        out
    };
    let mut huge_request = header(&["callerid=/evil", "service=/polymap/get_map", "md5sum=*", "persistent=1"]);
    huge_request.extend_from_slice(&0xC000_0000u32.to_le_bytes());
    huge_request.extend(std::iter::repeat_n(0u8, 64 * 1024));
    send(&huge_request, Duration::from_millis(500));
    // A silent peer: says nothing past the handshake timeout.
    let silent = std::thread::spawn({
        let tcpros = tcpros.clone();
        move || {
            let _s = TcpStream::connect(&tcpros).unwrap();
            std::thread::sleep(Duration::from_secs(7));
        }
    });
    // XML-RPC: not XML, and a body claiming a gigabyte.
    let addr = api.trim_start_matches("http://").trim_end_matches('/').to_string();
    let mut s = TcpStream::connect(&addr).unwrap();
    let _ = s.write_all(b"POST / HTTP/1.1\r\nContent-Length: 9\r\n\r\n\x00\xffnot xml");
    let _ = s.read_to_end(&mut Vec::new());
    let mut s = TcpStream::connect(&addr).unwrap();
    let _ = s.write_all(b"POST / HTTP/1.1\r\nContent-Length: 1000000000\r\n\r\n<methodCall>");
    let _ = s.read_to_end(&mut Vec::new());
    silent.join().unwrap();
    // A crowd: 300 connections at once, saying nothing. Those over the cap are closed at
    // once; the rest time out; then the node serves again.
    let crowd: Vec<TcpStream> = (0..300).filter_map(|_| TcpStream::connect(&tcpros).ok()).collect();
    std::thread::sleep(Duration::from_secs(1));
    drop(crowd);
    std::thread::sleep(Duration::from_secs(6));

    // The node serves on: a service call and a topic, through rospy's tools.
    let answer = core.command("rosservice", &["call", "/polymap/get_foothold", "point: {x: 0.42, y: 0.0, z: 0.30}"]);
    let status = core.command("rostopic", &["echo", "-n", "1", "/polymap/status"]).unwrap();
    let after = resident_kib(polymap.id());
    stop(&mut polymap);
    let log_text = std::fs::read_to_string(&log).unwrap();
    assert!(answer.unwrap().contains("foothold:"), "{log_text}");
    let refused: u64 = status
        .lines()
        .find_map(|l| l.trim().strip_prefix("requests_refused:"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("requests_refused in {status}"));
    assert!(refused >= 7, "refused {refused}:\n{log_text}");
    for why in [
        "over the 65536-byte limit",
        "ends after",
        "claims",
        "a service request of 3221225472 bytes is over the 65536-byte limit",
        "a connection header did not arrive within",
    ] {
        assert!(log_text.contains(why), "the log says {why:?}:\n{log_text}");
    }
    assert!(after < before + 16 * 1024, "resident memory grew from {before} KiB to {after} KiB");
}

/// Peers that hold on rather than lie (tests/peer/ros1_hostile.py, rospy and raw sockets): a
/// phantom pose 9 km away, a flood of publishers, idle service connections, a publisher that
/// stalls its messages, a crowd of 1 MiB XML-RPC bodies. polymap keeps serving through each,
/// bounds what each holds, gives the memory back, and maps no phantom.
#[test]
fn peers_that_hold_on_are_bounded_and_the_node_serves_on() {
    let core = Roscore::start();
    let dir = tempfile::tempdir().unwrap();
    let saved = dir.path().join("map.json");
    let port = free_loopback_port().unwrap();
    let sources = format!("{}[map]\nsnapshot_path = {:?}\n", mock_sources(), saved.display().to_string());
    let mut polymap = mapper(&core, dir.path(), 90, &sources, port);
    let log = dir.path().join("mapper.log");
    wait_for_node(&core, "/polymap", &log);
    // The real odometry, with its IMU-rate propagated poses, from a mock VINS on Zenoh.
    let vins_zenoh = dir.path().join("vins.json5");
    std::fs::write(&vins_zenoh, loopback_json5(None, &[port])).unwrap();
    let vins_config = dir.path().join("vins.toml");
    std::fs::write(&vins_config, format!("[zenoh]\nconfig_file = {:?}\n", vins_zenoh.display().to_string())).unwrap();
    let mut vins = Command::new(env!("CARGO_BIN_EXE_polymap"))
        .args(["mock-vins", root().join("mock_frames/straight_320").to_str().unwrap(), "--duration", "85", "--config"])
        .arg(&vins_config)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut probe = Command::new(PYTHON);
    probe.arg(root().join("tests/peer/ros1_hostile.py")).args(["--pid", &polymap.id().to_string()]);
    core.env(&mut probe);
    let out = probe.output().unwrap();
    let _ = vins.kill();
    let _ = vins.wait();
    stop(&mut polymap);
    let log_text = std::fs::read_to_string(&log).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "probe: {stdout}\n{}\n{log_text}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    eprintln!("{}", serde_json::to_string_pretty(&v).unwrap());
    let steps = &v["steps"];
    for (name, step) in steps.as_object().unwrap() {
        assert_eq!(step["serving"], true, "polymap stopped serving after {name}: {step}");
    }
    let mib = |name: &str| steps[name]["rss_mib"].as_f64().unwrap();
    let baseline = mib("baseline");
    // The phantom pose: no polygon 9 km out, in the map served or saved.
    let map: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&saved).unwrap()).unwrap();
    for p in map["polygons"].as_array().unwrap() {
        assert!(p["centroid"][0].as_f64().unwrap().abs() < 50.0, "a phantom polygon at {}", p["centroid"]);
    }
    // The flood of publishers: a topic takes 16 at most, refused and counted past them.
    let inbound = steps["publisher_flood"]["inbound"].as_u64().unwrap();
    assert!(inbound <= polymap::ros1::node::MAX_PUBLISHERS_PER_TOPIC as u64, "{inbound} publishers taken");
    assert!(log_text.contains("more publishers of /vins_estimator/odometry than the 16 taken"), "{log_text}");
    // Idle service connections are closed once their request is overdue; a 1 MiB request at once.
    assert_eq!(steps["idle_services"]["closed"], 300, "{}", steps["idle_services"]);
    assert_eq!(steps["idle_services"]["big_request_closed"], true);
    assert!(log_text.contains("a service request did not arrive within"), "{log_text}");
    // The stalling publisher: one connection at a time whatever its URIs, each given up after
    // its message's deadline.
    let stalled = &steps["stalling_publisher"];
    assert_eq!(stalled["most_open"], 1, "{stalled}");
    assert!(stalled["connections"].as_u64().unwrap() >= 1, "{stalled}");
    let held = stalled["held_s"].as_array().unwrap();
    assert!(!held.is_empty() && held.iter().all(|h| h.as_f64().unwrap() < 12.0), "{stalled}");
    // Memory: back near where it was after each.
    for name in ["publisher_flood_restored", "idle_services", "stalling_publisher", "xmlrpc_bodies"] {
        assert!(mib(name) < baseline + 24.0, "{name}: {:.0} MiB resident, {baseline:.0} MiB before", mib(name));
    }
}

/// `polymap demo --ros1` against `roscore`, by the README's commands as written: the master
/// on its default port, ROS 1's own tools, polymap_msgs built by catkin (the README's
/// `source devel/setup.bash` is the PYTHONPATH here). `cargo run --release --` is this
/// test build's binary.
#[test]
fn the_readme_s_ros1_commands_work_as_written() {
    assert!(
        std::net::TcpListener::bind("127.0.0.1:11311").is_ok(),
        "port 11311 is in use here: the README's roscore listens there"
    );
    let lines = common::readme_commands("ros1.rs");
    assert_eq!(lines.len(), 4, "{lines:?}");
    let home = tempfile::tempdir().unwrap();
    let shell = |line: &str| {
        let line = line.replace("cargo run --release --", env!("CARGO_BIN_EXE_polymap"));
        let mut c = Command::new("bash");
        c.args(["-c", line.trim_end_matches('&')])
            .env_remove("ROS_MASTER_URI")
            .env("ROS_HOME", home.path())
            .env("PYTHONPATH", python_messages())
            .current_dir(root());
        c
    };
    struct Background(Vec<Child>);
    impl Drop for Background {
        fn drop(&mut self) {
            // The demo, then roscore, as a user's Ctrl-C would.
            for child in self.0.iter_mut().rev() {
                stop(child);
            }
        }
    }
    let mut background = Background(Vec::new());
    let mut outputs = Vec::new();
    for line in &lines {
        if line.ends_with('&') {
            let log = std::fs::File::create(home.path().join(format!("bg{}.log", background.0.len()))).unwrap();
            background.0.push(shell(line).stdout(log.try_clone().unwrap()).stderr(log).spawn().unwrap());
            // Ready when the master answers (roscore) or lists the node (the demo); the next
            // commands wait for their topic or service themselves.
            let node = if line.starts_with("roscore") { "/rosout" } else { "/polymap" };
            let deadline = Instant::now() + Duration::from_secs(120);
            while !shell("rosnode list")
                .output()
                .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).lines().any(|l| l.trim() == node))
            {
                assert!(Instant::now() < deadline, "{line}: {node} never came up");
                std::thread::sleep(Duration::from_millis(300));
            }
        } else {
            let out = shell(&format!("timeout 90 {line}")).output().unwrap();
            let logs: String = (0..background.0.len())
                .map(|i| std::fs::read_to_string(home.path().join(format!("bg{i}.log"))).unwrap_or_default())
                .collect();
            assert!(
                out.status.success(),
                "{line}: {}{}\n{logs}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            outputs.push(String::from_utf8_lossy(&out.stdout).into_owned());
        }
    }
    let (markers, foothold) = (&outputs[0], &outputs[1]);
    assert!(markers.contains("ns: \"polygons_new\"") && markers.contains("points:"), "{markers}");
    assert!(markers.contains("type: 4"), "line strips: {markers}");
    assert!(foothold.contains("found: True"), "{foothold}");
}

/// roscpp peers (Debian's C++ `rosbag`, linked against roscpp): `rosbag record` subscribes
/// to polymap's topics and keeps them with the definitions polymap sent, from which rosbag's
/// Python reader decodes them (polymap_msgs is not on its path); `rosbag play` publishes
/// odometry that polymap decodes and refuses as not finite.
#[test]
fn roscpp_peers_record_polymap_s_topics_and_feed_it_odometry() {
    let core = Roscore::start();
    let dir = tempfile::tempdir().unwrap();
    let (mut polymap, log) = registered_mapper(&core, dir.path(), &mock_sources());
    let mut vins = Command::new(env!("CARGO_BIN_EXE_polymap"));
    vins.args(["mock-vins", "--ros1", "--duration", "25"])
        .arg(root().join("mock_frames/straight_320"))
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    core.env(&mut vins);
    let mut vins = vins.spawn().unwrap();

    let recorded = dir.path().join("recorded.bag");
    let topics = ["/polygon_new_markers", "/polymap/map", "/polymap/frame_polygons", "/polymap/status", "/tf"];
    let mut record = Command::new("rosbag");
    record.args(["record", "--duration=10", "-O"]).arg(&recorded).args(topics).stdout(Stdio::null());
    core.env(&mut record);
    let record = record.spawn().expect("rosbag (scripts/test.sh installs python3-rosbag)");

    let absurd = dir.path().join("absurd.bag");
    let bags = |args: &[&std::ffi::OsStr]| {
        let mut c = Command::new(PYTHON);
        c.arg(root().join("tests/peer/ros1_bags.py")).args(args).current_dir(dir.path());
        core.env(&mut c);
        // rosbag's reader has only what the bag says of polymap_msgs.
        c.env_remove("PYTHONPATH");
        let out = c.output().unwrap();
        assert!(out.status.success(), "ros1_bags.py {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    bags(&["write-absurd".as_ref(), absurd.as_os_str()]);
    std::thread::sleep(Duration::from_secs(3));
    // --delay: polymap connects to the new publisher before the messages go.
    let played = core.command("rosbag", &["play", "--delay=2", absurd.to_str().unwrap()]);
    let recorded_ok = record.wait_with_output().unwrap().status.success();
    let _ = vins.kill();
    let _ = vins.wait();
    stop(&mut polymap);
    let log_text = std::fs::read_to_string(&log).unwrap();
    played.unwrap();
    assert!(recorded_ok, "rosbag record failed");
    assert!(
        log_text.matches("pose on /vins_estimator/odometry refused").count() >= 5
            && log_text.contains("non-finite position [NaN"),
        "{log_text}"
    );

    let v: serde_json::Value = serde_json::from_str(bags(&["read".as_ref(), recorded.as_os_str()]).trim()).unwrap();
    eprintln!("{v}");
    for (topic, ty) in [
        ("/polygon_new_markers", "visualization_msgs/MarkerArray"),
        ("/polymap/map", "polymap_msgs/Map"),
        ("/polymap/frame_polygons", "polymap_msgs/FramePolygons"),
        ("/polymap/status", "polymap_msgs/Status"),
        ("/tf", "tf2_msgs/TFMessage"),
    ] {
        assert_eq!(v["topics"][topic]["type"], ty, "{v}");
        assert!(v["topics"][topic]["count"].as_u64().unwrap() >= 2, "{topic}: {v}");
    }
    assert!(v["map_polygons"].as_u64().unwrap() >= 5, "{v}");
    // genpy made the class from polymap's definition in the bag (a module of its own).
    assert!(v["map_class"].as_str().unwrap().starts_with("tmp"), "{v}");
    assert!(v["marker_points"].as_u64().unwrap() >= 20, "{v}");
    assert!(v["status_processed"].as_u64().unwrap() >= 10, "{v}");
}

/// Depth from a ROS image topic (`sources.depth.kind = "ros"`), published by a rospy node as
/// realsense-ros publishes the L515's, with VINS's poses: every frame polymap maps has the
/// polygons the same frame of the sequence gives offline, to the micrometre; an RGB image and
/// one that does not fit its camera_info are refused and counted.
#[test]
fn depth_from_a_ros_topic_gives_the_sequence_s_polygons_frame_by_frame() {
    let core = Roscore::start();
    let dir = tempfile::tempdir().unwrap();
    let seq_dir = root().join("mock_frames/straight_320");
    let seq = polymap::sequence::Sequence::open(&seq_dir).unwrap();
    // The offline twin rebuilds each frame's map frame from its update's drift_z alone, so
    // the drift is vertical here (MapUpdate carries no x, y or yaw yet).
    let sources = format!(
        "[sources.depth]\nkind = \"ros\"\nimage_unit_m = {}\n[sources.d435i]\nkind = \"none\"\n\
         [map]\ndrift_horizontal = false\n",
        seq.intrinsics.depth_scale
    );
    let (mut polymap, log) = registered_mapper(&core, dir.path(), &sources);
    let mut peer = Command::new(PYTHON);
    peer.arg(root().join("tests/peer/ros1_depth.py")).arg("--sequence").arg(&seq_dir);
    core.env(&mut peer);
    let out = peer.output().unwrap();
    let status = core.command("rostopic", &["echo", "-n", "1", "/polymap/status"]);
    stop(&mut polymap);
    let log_text = std::fs::read_to_string(&log).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer: {stdout}\n{}\n{log_text}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let frames = v["frames"].as_array().unwrap();
    eprintln!("{} of {} frames sent were mapped", frames.len(), v["sent"]);
    assert!(frames.len() >= 15, "{} of {} frames mapped:\n{log_text}", frames.len(), v["sent"]);

    let (polygons, worst) = common::frames_against_sequence(frames, &seq);
    eprintln!("{polygons} polygons in {} frames: worst vertex difference {worst:.2e} m", frames.len());
    assert!(polygons >= 3 * frames.len(), "{polygons} polygons");
    assert!(worst < 1e-6, "a vertex {worst} m off");
    assert!(log_text.contains("encoding \"rgb8\" is not a depth image"), "{log_text}");
    assert!(log_text.contains("but its camera_info says"), "{log_text}");
    let status = status.unwrap();
    assert!(status.contains("frames_not_extracted: 2"), "{status}");
}

/// The mapper's sources for a burst of changes: the mock stairs at 30 Hz (more frames than
/// the CPU twin extracts here: the newest frame wins), no D435i.
fn burst_sources() -> String {
    format!(
        "[sources.depth]\nsequence = {:?}\nfps = 30\n",
        root().join("mock_frames/straight_320").display().to_string()
    )
}

/// A rospy follower, node `name` (tests/peer/ros1_follower.py); `drop_every` > 0 loses every
/// n-th update it receives, as a lossy link would.
fn rospy_follower(core: &Roscore, dir: &Path, name: &str, drop_every: u32) -> common::PeerFollower {
    let mut cmd = Command::new(PYTHON);
    cmd.arg(root().join("tests/peer/ros1_follower.py")).args(["--name", name, "--drop-every", &drop_every.to_string()]);
    core.env(&mut cmd);
    common::PeerFollower::spawn(cmd, name, dir)
}

/// The mock VINS on ROS 1 (`/vins_estimator/odometry`) for `seconds`, waited for: then no
/// frame has a pose and the map stops changing.
fn ros1_vins_for(core: &Roscore, seconds: u32) {
    let mut vins = Command::new(env!("CARGO_BIN_EXE_polymap"));
    vins.args(["mock-vins", "--ros1", "--duration", &seconds.to_string()])
        .arg(root().join("mock_frames/straight_320"))
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    core.env(&mut vins);
    let status = vins.status().unwrap();
    assert!(status.success(), "mock-vins: {status}");
}

/// Planners on ROS 1 that share nothing with polymap (tests/peer/ros1_follower.py: rospy,
/// genpy's polymap_msgs, the README's contract written out again) keep their own copy of the
/// map from `map_updates` and the latched `map`, and each ends with get_map's map, polygon by
/// polygon and field by field:
/// - through a burst of changes (the camera at 30 Hz), one following every update and one
///   losing every fourth (it notices the gaps and takes a whole map);
/// - through a restart of polymap (SIGINT, a new run: a new epoch, the map built again from
///   empty by a shorter walk): both drop the old map for the new one;
/// - and one that joins once the map is built.
#[test]
fn rospy_followers_end_with_get_map_s_map_after_a_burst_a_restart_and_a_late_join() {
    struct Rospy {
        core: Roscore,
        dir: tempfile::TempDir,
        polymap: Option<Child>,
    }
    impl common::FollowerRig for Rospy {
        fn start(&mut self, run: &str) {
            let run_dir = self.dir.path().join(run);
            std::fs::create_dir_all(&run_dir).unwrap();
            self.polymap = Some(mapper(&self.core, &run_dir, 900, &burst_sources(), free_loopback_port().unwrap()));
            wait_for_node(&self.core, "/polymap", &run_dir.join("mapper.log"));
        }
        fn stop(&mut self) {
            stop(self.polymap.as_mut().unwrap());
        }
        fn walk(&mut self, seconds: u32) {
            ros1_vins_for(&self.core, seconds);
        }
        fn follower(&mut self, name: &str, drop_every: u32) -> common::PeerFollower {
            rospy_follower(&self.core, self.dir.path(), name, drop_every)
        }
    }
    let mut rig = Rospy { core: Roscore::start(), dir: tempfile::tempdir().unwrap(), polymap: None };
    common::followers_end_with_get_map(&mut rig, "latched");
}
