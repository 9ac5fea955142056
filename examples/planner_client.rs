//! A planner-side client: follows the versioned map (updates, the latched whole map, and
//! `get_map` when updates were missed) with polymap::interface::follower, then asks for the
//! foothold under a point, the way a footstep planner would every step. It is a
//! ROS 2 node on rmw_zenoh (polymap's own ROS 2 layer), so the same calls reach polymap
//! beside any other ROS 2 node.
//!
//! With a mapper running (`polymap demo --duration 60` in another shell, or `polymap run`):
//!   cargo run --release --example planner_client -- [ENDPOINT] [NAMESPACE]
//! ENDPOINT defaults to tcp/127.0.0.1:7447 (where `polymap demo` and rmw_zenohd listen);
//! NAMESPACE to polymap's, /polymap/leju.

use std::time::Duration;

use polymap::config::Config;
use polymap::interface::follower::MapFollower;
use polymap::interface::{Interface, convert};
use polymap::ros2::msg::{GetFootholdRequest, GetMapRequest, Point};
use polymap::ros2::{Node, NodeOptions, RosName};

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let endpoint = args.next().unwrap_or_else(|| "tcp/127.0.0.1:7447".into());
    let mut config = Config::default();
    if let Some(ns) = args.next() {
        config.ros2.namespace = RosName::parse(&ns).map_err(|e| anyhow::anyhow!(e))?;
    }
    let session = polymap::ros2::session::open(polymap::ros2::session::connecting_to(&endpoint)?).await?;
    let node = Node::new(
        &session,
        NodeOptions { namespace: RosName::root(), name: "planner_client".into(), ..config.ros2.node_options() },
    )
    .await?;
    let interface = Interface::new(&config);

    // Follow the map as the planner contract says (README, "The planner contract"): updates
    // and the latched whole map into one follower, a whole map asked for whenever it says so.
    let (update_tx, mut updates) = tokio::sync::mpsc::unbounded_channel();
    let _updates = node
        .subscribe(&interface.map_updates, move |u| match u {
            Ok(u) => drop(update_tx.send(u)),
            Err(e) => eprintln!("undecodable update: {e}"),
        })
        .await?;
    let (map_tx, mut maps) = tokio::sync::mpsc::unbounded_channel();
    let _map = node
        .subscribe(&interface.map, move |m| match m {
            Ok(m) => drop(map_tx.send(m)),
            Err(e) => eprintln!("undecodable map: {e}"),
        })
        .await?;
    let get_map = node.client(&interface.get_map).await?;
    let mut follower = MapFollower::new();
    let until = tokio::time::Instant::now() + Duration::from_secs(3);
    loop {
        if follower.needs_whole_map()
            && let Ok(r) = get_map.call(&GetMapRequest::default(), Duration::from_secs(2)).await
        {
            follower.on_map(r.map);
        }
        tokio::select! {
            Some(u) = updates.recv() => {
                let (added, changed, removed, drift) = (u.added.len(), u.changed.len(), u.removed.len(), u.drift_z);
                let version = u.version;
                let outcome = follower.on_update(u);
                println!(
                    "update to version {version}: {added} added, {changed} changed, {removed} removed; \
                     drift {:.1} mm; {outcome:?}",
                    drift * 1e3
                );
            }
            Some(m) = maps.recv() => drop(follower.on_map(m)),
            _ = tokio::time::sleep_until(until) => break,
        }
    }
    let Some(map) = follower.map() else { anyhow::bail!("no map from {endpoint}: is a mapper running?") };
    println!(
        "map: {} polygons in frame {:?}, version {} ({:?})",
        map.polygons.len(),
        map.header.frame_id,
        map.version,
        follower.counters
    );
    for p in &map.polygons {
        let label = convert::label_of(p.label).map_or("?".into(), |l| format!("{l:?}").to_lowercase());
        let steppable: usize = p.insets.iter().map(|r| r.boundary.len()).sum();
        println!(
            "  {:>4} {:<8} step {:>2}  area {:.3} m2  z {:.3} m  inset {} piece(s), {steppable} vertices",
            p.id,
            label,
            p.step,
            p.area,
            p.centroid.z,
            p.insets.len()
        );
    }

    // The foothold under a point on the second tread of the mock stairs.
    let get_foothold = node.client(&interface.get_foothold).await?;
    let request = GetFootholdRequest { point: Point { x: 0.42, y: 0.0, z: 0.30 } };
    let f = get_foothold.call(&request, Duration::from_secs(5)).await?.foothold;
    println!(
        "foothold: found {} (contains {}), polygon {}, piece of {} vertices, {:.3} m away",
        f.found,
        f.contains,
        f.polygon_id,
        f.piece.len(),
        f.distance
    );
    Ok(())
}
