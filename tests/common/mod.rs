//! What the end-to-end tests share: paths, loopback configs, and a planner that follows the
//! map as polymap::interface::follower says.
#![allow(dead_code)] // each test binary uses its own part

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::Arc;
use std::time::Duration;

use polymap::config::Config;
use polymap::interface::Interface;
use polymap::interface::follower::{FollowerCounters, MapFollower};
use polymap::ros2::msg::{GetMap, GetMapRequest, Map, MapUpdate, Polygon};
use polymap::ros2::session::{loopback, loopback_json5};
use polymap::ros2::{Client, Node, NodeOptions, RosName};

pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The README's commands in the `sh` block after its `<!-- tests/<file>` marker, one a line.
pub fn readme_commands(test_file: &str) -> Vec<String> {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let marker = readme.find(&format!("<!-- tests/{test_file}")).expect("the README marks the commands");
    let block = &readme[marker..];
    let start = block.find("```sh\n").expect("a sh block after the marker") + 6;
    let end = block[start..].find("```").unwrap();
    block[start..start + end].lines().map(str::trim).filter(|l| !l.is_empty()).map(String::from).collect()
}

pub fn json5(dir: &Path, name: &str, listen: Option<u16>, connect: &[u16]) -> String {
    let path = dir.join(format!("{name}.json5"));
    std::fs::write(&path, loopback_json5(listen, connect)).unwrap();
    path.display().to_string()
}

/// A session connected to the mapper's peer on `port` (which may not listen yet), and a node on it.
pub async fn planner_node(port: u16, name: &str) -> (zenoh::Session, Arc<Node>) {
    node_on(|| loopback(None, &[port]), name).await
}

/// A session made with `config` once it reaches another peer or a router, and a node on it.
pub async fn node_on(config: impl Fn() -> zenoh::Config, name: &str) -> (zenoh::Session, Arc<Node>) {
    for _ in 0..100 {
        if let Ok(s) = polymap::ros2::session::open(config()).await
            && (s.info().peers_zid().await.next().is_some() || s.info().routers_zid().await.next().is_some())
        {
            let config = Config::default();
            let options = NodeOptions { namespace: RosName::root(), name: name.into(), ..config.ros2.node_options() };
            let node = Arc::new(Node::new(&s, options).await.unwrap());
            return (s, node);
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("no Zenoh peer or router answered");
}

/// What one follower ended with.
pub struct Followed {
    pub map: Option<Map>,
    pub counters: FollowerCounters,
    /// The same stream applied without versions: every update as it comes, the whole map
    /// when its answer comes (what a planner did before versions).
    pub naive: BTreeMap<u64, Polygon>,
}

/// A planner following the map: subscribe to the updates and the whole map, ask for the
/// whole map, then apply what comes, asking again whenever the follower says so; `drop_every` updates received, one
/// is lost. Ends when `stop` says so, once what arrived is applied.
pub async fn follow(
    node: Arc<Node>,
    interface: Interface,
    drop_every: Option<u64>,
    mut stop: tokio::sync::watch::Receiver<bool>,
) -> Followed {
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<MapUpdate>();
    let _updates = node
        .subscribe(&interface.map_updates, move |m| {
            let _ = tx.send(m.expect("map updates decode"));
        })
        .await
        .unwrap();
    // The whole map, latched and republished each time it changes (at most once a second):
    // the way back for a follower that lost the last update of a burst and so has no later
    // one to notice the gap by.
    let (whole_tx, mut whole_rx) = tokio::sync::mpsc::unbounded_channel::<Map>();
    let _whole = node
        .subscribe(&interface.map, move |m| {
            let _ = whole_tx.send(m.expect("the whole map decodes"));
        })
        .await
        .unwrap();
    let get_map = node.client(&interface.get_map).await.unwrap();
    let mut follower = MapFollower::new();
    let mut naive: BTreeMap<u64, Polygon> = BTreeMap::new();
    let mut received = 0u64;
    let mut take = |u: MapUpdate, follower: &mut MapFollower, naive: &mut BTreeMap<u64, Polygon>| {
        received += 1;
        if drop_every.is_some_and(|n| received.is_multiple_of(n)) {
            return;
        }
        for id in &u.removed {
            naive.remove(id);
        }
        for p in u.added.iter().chain(&u.changed) {
            naive.insert(p.id, p.clone());
        }
        follower.on_update(u);
    };
    loop {
        if follower.needs_whole_map()
            && let Ok(r) = get_map.call(&GetMapRequest::default(), Duration::from_secs(5)).await
        {
            naive = r.map.polygons.iter().map(|p| (p.id, p.clone())).collect();
            follower.on_map(r.map);
        }
        tokio::select! {
            u = rx.recv() => match u {
                Some(u) => take(u, &mut follower, &mut naive),
                None => break,
            },
            m = whole_rx.recv() => if let Some(m) = m {
                follower.on_map(m);
            },
            _ = stop.changed() => break,
        }
    }
    while let Ok(u) = rx.try_recv() {
        take(u, &mut follower, &mut naive);
    }
    while let Ok(m) = whole_rx.try_recv() {
        follower.on_map(m);
    }
    if follower.needs_whole_map()
        && let Ok(r) = get_map.call(&GetMapRequest::default(), Duration::from_secs(5)).await
    {
        follower.on_map(r.map);
    }
    Followed { map: follower.map(), counters: follower.counters, naive }
}

/// `polymap run` on the mock camera replaying `seq` at `fps` (CPU twin), a Zenoh peer
/// listening on loopback `port`, with `extra` TOML appended to its config and its log in
/// `dir/mapper.log`; and a config for a mock VINS that connects to it.
pub fn start_mapper(dir: &Path, seq: &Path, port: u16, fps: u32, extra: &str, seconds: u64) -> (Child, PathBuf) {
    let mapper_cfg = dir.join("mapper.toml");
    let toml = format!(
        "[sources.depth]\nsequence = {:?}\nfps = {fps}\n[pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n{extra}",
        seq.display().to_string(),
        json5(dir, "mapper", Some(port), &[])
    );
    std::fs::write(&mapper_cfg, toml).unwrap();
    let vins_cfg = dir.join("vins.toml");
    std::fs::write(&vins_cfg, format!("[zenoh]\nconfig_file = {:?}\n", json5(dir, "vins", None, &[port]))).unwrap();
    let mapper = Command::new(env!("CARGO_BIN_EXE_polymap"))
        .args(["run", "--duration", &seconds.to_string(), "--config"])
        .arg(&mapper_cfg)
        .stderr(std::fs::File::create(dir.join("mapper.log")).unwrap())
        .spawn()
        .unwrap();
    (mapper, vins_cfg)
}

/// The map once it has stopped changing: asked every 1.5 s until two answers agree.
pub async fn settled_map(get_map: &Client<GetMap>) -> Map {
    let mut last_version = None;
    loop {
        tokio::time::sleep(Duration::from_millis(1500)).await;
        let m = get_map.call(&GetMapRequest::default(), Duration::from_secs(5)).await.unwrap().map;
        if last_version == Some(m.version) {
            return m;
        }
        last_version = Some(m.version);
    }
}

/// A depth source test's frames, as its camera peer prints them (each frame polymap mapped:
/// its index `k` in `seq`, the map's `drift_z` then, and the frame polygons' outlines)
/// against the same frames extracted offline with the CPU twin, posed by the sequence less
/// the drift: (polygons compared, the worst vertex difference in metres). Every frame must
/// have as many polygons, with as long outlines, as offline.
pub fn frames_against_sequence(frames: &[serde_json::Value], seq: &polymap::sequence::Sequence) -> (usize, f64) {
    let config = Config::default();
    let pipeline = polymap::config::PipelineConfig { backend: polymap::config::Backend::Cpu, ..config.pipeline };
    let mut extractor = polymap::extract::Extractor::new(&pipeline).unwrap();
    let (mut worst, mut polygons) = (0.0f64, 0);
    for f in frames {
        let k = f["k"].as_u64().unwrap() as usize;
        let drift = f["drift_z"].as_f64().expect("the frame's map update");
        let extracted = extractor.extract(&seq.depth(k).unwrap(), &seq.intrinsics).unwrap().polygons;
        let t = nalgebra::Translation3::new(0.0, 0.0, -drift) * seq.poses[k].transform;
        let offline: Vec<_> = extracted.polygons.iter().map(|p| p.transformed(&t)).collect();
        let offline = polymap::interface::convert::frame_polygons(0, "map", &offline);
        let live = f["polygons"].as_array().unwrap();
        assert_eq!(live.len(), offline.polygons.len(), "frame {k}: polygons live and offline");
        for (l, o) in live.iter().zip(&offline.polygons) {
            let l = l.as_array().unwrap();
            assert_eq!(l.len(), o.boundary.len(), "frame {k}: outline lengths");
            for (a, b) in l.iter().zip(&o.boundary) {
                let a: Vec<f64> = a.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
                worst = worst.max((a[0] - b.x).abs()).max((a[1] - b.y).abs()).max((a[2] - b.z).abs());
            }
        }
        polygons += live.len();
    }
    (polygons, worst)
}

/// A follower of tests/peer (ros1_follower.py, ros2_follower.py): a planner's copy of the map
/// kept from the message definitions and the README's contract alone. The test drives it on
/// its stdin (`check LABEL`, `quit`) and reads its JSON lines; its stderr goes to
/// `dir/<name>.stderr`. Killed when dropped.
pub struct PeerFollower {
    pub name: String,
    child: Child,
    stdin: std::process::ChildStdin,
    lines: std::sync::mpsc::Receiver<serde_json::Value>,
    stderr: PathBuf,
}

impl PeerFollower {
    pub fn spawn(mut cmd: Command, name: &str, dir: &Path) -> PeerFollower {
        use std::io::BufRead;
        use std::process::Stdio;
        let stderr = dir.join(format!("{name}.stderr"));
        cmd.stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(std::fs::File::create(&stderr).unwrap());
        let mut child = cmd.spawn().unwrap_or_else(|e| panic!("{name}: {e}"));
        let stdout = child.stdout.take().unwrap();
        let stdin = child.stdin.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        let who = name.to_string();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                match serde_json::from_str::<serde_json::Value>(&line) {
                    Ok(v) => {
                        if tx.send(v).is_err() {
                            break;
                        }
                    }
                    Err(_) => eprintln!("{who}: {line}"),
                }
            }
        });
        PeerFollower { name: name.into(), child, stdin, lines, stderr }
    }

    fn send(&mut self, command: &str) {
        use std::io::Write;
        let sent = writeln!(self.stdin, "{command}").and_then(|_| self.stdin.flush());
        if let Err(e) = sent {
            panic!("{}: {command:?}: {e}; it said:\n{}", self.name, self.said());
        }
    }

    fn said(&self) -> String {
        std::fs::read_to_string(&self.stderr).unwrap_or_default()
    }

    /// Its next line that has `key`; `limit` bounds a hang only.
    pub fn expect(&mut self, key: &str, limit: Duration) -> serde_json::Value {
        let deadline = std::time::Instant::now() + limit;
        loop {
            match self.lines.recv_timeout(deadline.saturating_duration_since(std::time::Instant::now())) {
                Ok(v) if v.get(key).is_some() => return v,
                Ok(_) => {}
                Err(e) => panic!(
                    "{}: no {key:?} line within {limit:?} ({e}; exited: {:?}); it said:\n{}",
                    self.name,
                    self.child.try_wait(),
                    self.said()
                ),
            }
        }
    }

    /// Once it holds a map and get_map answered it.
    pub fn ready(&mut self) -> serde_json::Value {
        self.expect("ready", Duration::from_secs(120))
    }

    /// Asks it to compare its copy with get_map once the map stops changing; [`Self::checked`] reads the answer.
    pub fn check(&mut self, label: &str) {
        self.send(&format!("check {label}"));
    }

    pub fn checked(&mut self) -> serde_json::Value {
        self.expect("check", Duration::from_secs(400))
    }

    pub fn quit(&mut self) -> serde_json::Value {
        self.send("quit");
        let bye = self.expect("bye", Duration::from_secs(60));
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        while std::time::Instant::now() < deadline && !matches!(self.child.try_wait(), Ok(Some(_))) {
            std::thread::sleep(Duration::from_millis(100));
        }
        bye
    }
}

impl Drop for PeerFollower {
    fn drop(&mut self) {
        if !matches!(self.child.try_wait(), Ok(Some(_))) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// A follower's check, held to the contract: it ended with get_map's map, exactly.
pub fn assert_holds_the_map(check: &serde_json::Value, who: &str) {
    assert_eq!(check["settled"], true, "{who}: the map settled: {check:#}");
    assert_eq!(check["equal"], true, "{who}: its copy is get_map's map: {check:#}");
    assert_eq!(check["held"], serde_json::json!([check["epoch"], check["version"]]), "{who}: {check:#}");
    assert_eq!(check["polygons"], check["map_polygons"], "{who}: {check:#}");
}

/// Blocks until something accepts TCP connections on loopback port `port`; fails only on a hang.
pub fn wait_for_listener(port: u16, within: Duration) {
    let started = std::time::Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(started.elapsed() < within, "nothing listens on port {port} after {within:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// What a follower scenario needs of one transport: polymap started and stopped, a walk of
/// the mock VINS, and a follower that shares no code with polymap.
pub trait FollowerRig {
    /// Starts a run of polymap (a new epoch) in `run`, ready for followers.
    fn start(&mut self, run: &str);
    /// Ends the current run.
    fn stop(&mut self);
    /// The mock VINS walking for `seconds`, waited for: then the map stops changing.
    fn walk(&mut self, seconds: u32);
    /// A follower node `name`; `drop_every` > 0 loses every n-th update, as a lossy link would.
    fn follower(&mut self, name: &str, drop_every: u32) -> PeerFollower;
}

/// The contract's scenario, the same on every transport: a burst of changes (one follower
/// taking every update, one losing every fourth), a restart of polymap (a new epoch, a shorter
/// walk), and a late joiner; each follower ends with get_map's map. `latched` names the
/// whole-map topic's kind in messages.
pub fn followers_end_with_get_map(rig: &mut impl FollowerRig, latched: &str) {
    rig.start("run1");
    let mut follower = rig.follower("follower", 0);
    let mut lossy = rig.follower("lossy_follower", 4);
    let (joined, lossy_joined) = (follower.ready(), lossy.ready());
    eprintln!("joined: {joined}\n        {lossy_joined}");

    // A burst: 12 s of odometry with the camera at 30 Hz.
    rig.walk(12);
    follower.check("burst");
    lossy.check("burst");
    let (a, a_lossy) = (follower.checked(), lossy.checked());
    eprintln!("after the burst: {a}\n                 {a_lossy}");
    assert_holds_the_map(&a, "the follower after the burst");
    assert_holds_the_map(&a_lossy, "the lossy follower after the burst");
    assert!(a["version"].as_u64().unwrap() >= 10 && a["map_polygons"].as_u64().unwrap() >= 3, "a burst: {a}");
    assert!(a["counters"]["applied"].as_u64().unwrap() >= 1, "the follower followed by the updates: {a}");
    assert!(a_lossy["counters"]["dropped"].as_u64().unwrap() >= 1, "{a_lossy}");
    assert!(a_lossy["counters"]["gaps"].as_u64().unwrap() >= 1, "the lossy follower saw its gaps: {a_lossy}");

    // A restart: a new run (a new epoch) builds the map again from empty, with a shorter walk
    // (fewer versions than the first run's).
    rig.stop();
    rig.start("run2");
    rig.walk(6);
    follower.check("restart");
    lossy.check("restart");
    let (b, b_lossy) = (follower.checked(), lossy.checked());
    eprintln!("after the restart: {b}\n                   {b_lossy}");
    for (check, who) in [(&b, "the follower"), (&b_lossy, "the lossy follower")] {
        assert_holds_the_map(check, &format!("{who} after the restart"));
        assert_ne!(check["epoch"], a["epoch"], "{who}: a new run: {check}");
        assert_eq!(check["epochs"], serde_json::json!([a["epoch"], check["epoch"]]), "{who}: {check}");
    }
    assert!(b["map_polygons"].as_u64().unwrap() >= 3, "the new run mapped: {b}");

    // A late joiner, once the map is built.
    let mut late = rig.follower("late_follower", 0);
    let late_joined = late.ready();
    late.check("late");
    let c = late.checked();
    eprintln!("the late joiner: {late_joined}\n                 {c}");
    assert_holds_the_map(&c, "the late joiner");
    assert_eq!((&c["epoch"], &c["version"]), (&b["epoch"], &b["version"]), "{c}");
    assert!(c["topic_maps"].as_u64().unwrap() >= 1, "the whole map from the {latched} `map` topic: {c}");
    for f in [&mut follower, &mut lossy, &mut late] {
        f.quit();
    }
    rig.stop();
}
