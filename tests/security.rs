//! The robot's security setup as shipped (config/zenoh/robot/: a router with mutual TLS and
//! access control, and a client config per role), with certificates made at test time: the
//! router (`polymap router`), the mapper (`polymap run`) and the mock VINS as processes, a
//! planner, an intruder and a rogue as sessions of this test.
//!
//! - A rogue whose certificate the robot's CA did not sign cannot connect at all.
//! - An intruder with a certificate of the CA but no role may connect, and do nothing: its
//!   odometry (poses 123 m up) never reaches anyone, its queryable on the
//!   foothold service never sees a query, and the planner gets the mapper's answer only.
//! - Known peers beyond their jobs do nothing either: a planner's odometry, its queryable on
//!   polymap's service and its forged map updates, and VINS's forged map updates and its
//!   subscription to them, reach no one.
//! - VINS, polymap and the planner do their jobs through the router, which starts after
//!   polymap: polymap waits for it.

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use polymap::config::Config;
use polymap::interface::{Interface, OdometryTopic, convert};
use polymap::pose::RawPose;
use polymap::ros2::graph::Endpoint;
use polymap::ros2::msg::{Foothold, GetFoothold, GetFootholdRequest, GetFootholdResponse, Point};
use polymap::ros2::{Node, NodeOptions, RosName, cdr};
mod common;
use common::wait_for_listener;

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, KeyPair, KeyUsagePurpose, SanType,
};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A certificate authority: its certificate and key.
struct Ca {
    cert: rcgen::Certificate,
    key: KeyPair,
}

fn ca(name: &str) -> Ca {
    let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
    params.distinguished_name.push(DnType::CommonName, name);
    params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign, KeyUsagePurpose::DigitalSignature];
    let key = KeyPair::generate().unwrap();
    Ca { cert: params.self_signed(&key).unwrap(), key }
}

/// `<dir>/<name>.pem` and `.key`: a certificate with common name `name`, signed by `ca`,
/// good for both ends of a TLS link on this machine.
fn issue(ca: &Ca, dir: &Path, name: &str) {
    let mut params = CertificateParams::new(vec!["localhost".to_string()]).unwrap();
    params.subject_alt_names.push(SanType::IpAddress("127.0.0.1".parse().unwrap()));
    params.distinguished_name.push(DnType::CommonName, name);
    params.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth, ExtendedKeyUsagePurpose::ClientAuth];
    params.key_usages = vec![KeyUsagePurpose::DigitalSignature, KeyUsagePurpose::KeyEncipherment];
    let key = KeyPair::generate().unwrap();
    let cert = params.signed_by(&key, &ca.cert, &ca.key).unwrap();
    std::fs::write(dir.join(format!("{name}.pem")), cert.pem()).unwrap();
    std::fs::write(dir.join(format!("{name}.key")), key.serialize_pem()).unwrap();
}

/// A shipped robot config (config/zenoh/robot/<name>.json5) with its certificates in `tls`
/// and its port `port` on loopback, written to `<tls>/<as_name>.json5`.
fn shipped(name: &str, as_name: &str, tls: &Path, port: u16) -> std::path::PathBuf {
    let text = std::fs::read_to_string(root().join("config/zenoh/robot").join(format!("{name}.json5"))).unwrap();
    let text = text
        .replace("/etc/polymap/tls/", &format!("{}/", tls.display()))
        .replace("tls/0.0.0.0:7447", &format!("tls/127.0.0.1:{port}"))
        .replace("tls/localhost:7447", &format!("tls/localhost:{port}"))
        .replace(&format!("/{name}.key"), &format!("/{as_name}.key"))
        .replace(&format!("/{name}.pem"), &format!("/{as_name}.pem"));
    let path = tls.join(format!("{as_name}.json5"));
    std::fs::write(&path, text).unwrap();
    path
}

async fn open(config: &Path) -> Result<zenoh::Session, polymap::ros2::Ros2Error> {
    polymap::ros2::session::open(polymap::ros2::session::config(config).unwrap()).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_authenticated_authorised_peers_reach_polymap() {
    let dir = tempfile::tempdir().unwrap();
    let tls = dir.path();
    let robot = ca("robot CA");
    for name in ["router", "polymap", "vins", "planner", "intruder"] {
        issue(&robot, tls, name);
    }
    let elsewhere = ca("a CA the robot does not know");
    issue(&elsewhere, tls, "rogue");
    std::fs::write(tls.join("ca.pem"), robot.cert.pem()).unwrap();
    let port = polymap::ros2::session::free_loopback_port().unwrap();

    let bin = env!("CARGO_BIN_EXE_polymap");
    let mapper_config = tls.join("mapper.toml");
    std::fs::write(
        &mapper_config,
        format!(
            "[sources.depth]\nsequence = {:?}\nfps = 8\n[pipeline]\nbackend = \"cpu\"\n[zenoh]\nconfig_file = {:?}\n",
            root().join("mock_frames/straight_320").display().to_string(),
            shipped("polymap", "polymap", tls, port).display().to_string()
        ),
    )
    .unwrap();
    // Longer than the test waits for it below: a slow start fails there, with its log.
    let mut mapper = Command::new(bin)
        .args(["run", "--duration", "90", "--config"])
        .arg(&mapper_config)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(tls.join("mapper.log")).unwrap())
        .spawn()
        .unwrap();
    let logs = || {
        let read = |name: &str| std::fs::read_to_string(tls.join(name)).unwrap_or_default();
        format!("polymap's log:\n{}\nthe router's:\n{}", read("mapper.log"), read("router.log"))
    };
    // The router comes up after polymap, as it may at boot: polymap waits for it.
    std::thread::sleep(Duration::from_millis(1500));
    let mut router = Command::new(bin)
        .args(["router", "--duration", "60", "--config"])
        .arg(shipped("router", "router", tls, port))
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(tls.join("router.log")).unwrap())
        .spawn()
        .unwrap();
    wait_for_listener(port, Duration::from_secs(20));
    let vins_config = tls.join("vins.toml");
    std::fs::write(
        &vins_config,
        format!("[zenoh]\nconfig_file = {:?}\n", shipped("vins", "vins", tls, port).display().to_string()),
    )
    .unwrap();
    let mut vins = Command::new(bin)
        .args([
            "mock-vins",
            root().join("mock_frames/straight_320").to_str().unwrap(),
            "--rate",
            "100",
            "--duration",
            "32",
            "--config",
        ])
        .arg(&vins_config)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();

    // A rogue with a certificate of another CA is not let in.
    let rogue = open(&shipped("planner", "rogue", tls, port)).await;
    assert!(rogue.is_err(), "the rogue connected");

    let config = Config::default();
    let interface = Interface::new(&config);
    let node_options =
        |name: &str| NodeOptions { namespace: RosName::root(), name: name.into(), ..config.ros2.node_options() };
    let planner_session = open(&shipped("planner", "planner", tls, port)).await.expect("the planner connects");
    let planner = Node::new(&planner_session, node_options("planner")).await.unwrap();
    let intruder_session =
        open(&shipped("planner", "intruder", tls, port)).await.expect("a certificate of the CA connects");
    let intruder = Node::new(&intruder_session, node_options("intruder")).await.unwrap();
    // polymap answers through the router once its retries have found it (they back off to
    // 4 s apart).
    let get_map = planner.client(&interface.get_map).await.unwrap();
    let started = std::time::Instant::now();
    while let Err(e) = get_map.call(&Default::default(), Duration::from_secs(2)).await {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "polymap never answered through the router: {e}\n{}",
            logs()
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }

    // What the planner sees: map updates, and the odometry (real: z under 10 m; the
    // intruder's phantom: z = 123 m).
    let (updates, real_poses, phantom_poses) =
        (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    // A sample that does not decode as a MapUpdate is a peer's forgery (polymap's decode).
    let forged_updates = Arc::new(AtomicU64::new(0));
    let (u, f) = (updates.clone(), forged_updates.clone());
    let _updates = planner
        .subscribe(&interface.map_updates, move |m| {
            let counter = if m.is_ok() { &u } else { &f };
            counter.fetch_add(1, Ordering::Relaxed);
        })
        .await
        .unwrap();
    let OdometryTopic::Odometry(odometry) = interface.odometry.clone() else { unreachable!() };
    let (r, p) = (real_poses.clone(), phantom_poses.clone());
    let _poses = planner
        .subscribe(&odometry, move |m| {
            if let Ok(m) = m {
                let counter = if m.pose.pose.position.z == 123.0 { &p } else { &r };
                counter.fetch_add(1, Ordering::Relaxed);
            }
        })
        .await
        .unwrap();

    // The intruder: odometry of its own, and a queryable on the foothold service.
    let phantom = intruder.publisher(&odometry).await.unwrap();
    let hash = polymap::ros2::msg::service_hash::<GetFoothold>();
    let key = intruder.data_key(&Endpoint {
        name: &interface.get_foothold.name,
        type_name: "polymap_msgs/srv/GetFoothold",
        type_hash: &hash,
    });
    let asked = Arc::new(AtomicU64::new(0));
    let a = asked.clone();
    let rogue_key = key.clone();
    let _queryable = intruder_session
        .declare_queryable(key.clone())
        .complete(true)
        .callback(move |q| {
            a.fetch_add(1, Ordering::Relaxed);
            let bogus =
                GetFootholdResponse { foothold: Foothold { found: true, polygon_id: 999_999, ..Foothold::default() } };
            let _ = zenoh::Wait::wait(q.reply(rogue_key.clone(), cdr::to_vec(&bogus)));
        })
        .await
        .unwrap();
    // Roles beyond their jobs, each with a certificate of the CA: a second planner that
    // publishes odometry (poses 123 m up too), forges map updates and serves the foothold
    // service; VINS that forges map updates and subscribes to them.
    let update_key = planner.data_key(&Endpoint {
        name: &interface.map_updates.name,
        type_name: "polymap_msgs/msg/MapUpdate",
        type_hash: &polymap::ros2::types::message_hash::<polymap::ros2::msg::MapUpdate>(),
    });
    let planner2_session = open(&shipped("planner", "planner", tls, port)).await.expect("a second planner connects");
    let planner2 = Node::new(&planner2_session, node_options("planner2")).await.unwrap();
    let planner_phantom = planner2.publisher(&odometry).await.unwrap();
    let planner_asked = Arc::new(AtomicU64::new(0));
    let a = planner_asked.clone();
    let _planner_queryable = planner2_session
        .declare_queryable(key.clone())
        .complete(true)
        .callback(move |_| {
            a.fetch_add(1, Ordering::Relaxed);
        })
        .await
        .unwrap();
    let vins_session = open(&shipped("vins", "vins", tls, port)).await.expect("VINS connects");
    let vins_heard = Arc::new(AtomicU64::new(0));
    let h = vins_heard.clone();
    let _vins_updates = vins_session
        .declare_subscriber(update_key.clone())
        // Its own forgeries reach it within its session; polymap's updates may not.
        .callback(move |sample| {
            if sample.payload().to_bytes()[..] != [0xde, 0xad, 0xbe, 0xef] {
                h.fetch_add(1, Ordering::Relaxed);
            }
        })
        .await
        .unwrap();
    for k in 0..100 {
        let raw = RawPose {
            stamp_ns: polymap::clock::now_ns(),
            position: [0.1 * k as f64, 0.0, 123.0],
            quat_xyzw: [0.0, 0.0, 0.0, 1.0],
        };
        phantom.put(&convert::odometry(&raw, "world", "body")).await.unwrap();
        planner_phantom.put(&convert::odometry(&raw, "world", "body")).await.unwrap();
        for session in [&planner2_session, &vins_session] {
            session.put(update_key.clone(), vec![0xde, 0xad, 0xbe, 0xef]).await.unwrap();
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    // The planner asks for the foothold on tread 2, taking every reply that comes.
    let replies = planner_session
        .get(key)
        .payload(cdr::to_vec(&GetFootholdRequest { point: Point { x: 0.42, y: 0.0, z: 0.30 } }))
        .target(zenoh::query::QueryTarget::AllComplete)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(Duration::from_secs(5))
        .await
        .unwrap();
    let mut answers = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        let sample = reply.result().expect("an answer, not an error");
        answers.push(cdr::from_slice::<GetFootholdResponse>(&sample.payload().to_bytes()).unwrap().foothold);
    }

    let map = get_map.call(&Default::default(), Duration::from_secs(5)).await;

    let status = tokio::task::spawn_blocking(move || {
        let _ = Command::new("kill").args(["-TERM", &mapper.id().to_string()]).status();
        mapper.wait()
    })
    .await
    .unwrap()
    .unwrap();
    let _ = vins.kill();
    let _ = router.kill();
    let _ = (vins.wait(), router.wait());
    let map = match map {
        Ok(reply) => reply.map,
        Err(e) => panic!("the planner gets no map: {e}\n{}", logs()),
    };

    assert!(status.success(), "polymap ended with {status} on SIGTERM: {}", logs());
    assert!(updates.load(Ordering::Relaxed) >= 10, "the planner gets the map updates: {}", logs());
    assert!(real_poses.load(Ordering::Relaxed) >= 200, "the planner sees VINS's odometry");
    assert_eq!(
        phantom_poses.load(Ordering::Relaxed),
        0,
        "a phantom odometry (the intruder's or a planner's) reached the planner"
    );
    // Had the phantom poses reached the mapper, its map would hold surfaces 123 m up.
    assert!(map.polygons.len() >= 5, "{} polygons", map.polygons.len());
    assert!(map.polygons.iter().all(|p| p.centroid.z < 2.0), "the intruder's odometry reached the mapper");
    assert_eq!(asked.load(Ordering::Relaxed), 0, "a query reached the intruder's queryable");
    assert_eq!(planner_asked.load(Ordering::Relaxed), 0, "a query reached a planner's queryable");
    assert_eq!(
        forged_updates.load(Ordering::Relaxed),
        0,
        "a planner's or VINS's forged map update reached the planner"
    );
    assert_eq!(vins_heard.load(Ordering::Relaxed), 0, "VINS subscribed to polymap's map updates");
    assert_eq!(answers.len(), 1, "one answer, the mapper's: {answers:?}");
    assert!(answers[0].found && answers[0].polygon_id != 999_999, "{:?}", answers[0]);
}
