//! A planner-side client: follows the map's updates, asks for the whole map once, and asks
//! for the foothold under a point, the way a footstep planner would every step.
//!
//! With a mapper running (`polymap demo --duration 60` in another shell, or `polymap run`):
//!   cargo run --example planner_client -- [ZENOH_JSON5] [PREFIX]
//! ZENOH_JSON5 defaults to Zenoh's defaults (a peer that scouts for others);
//! PREFIX defaults to polymap/leju.

use std::time::Duration;

use polymap::ros::{self, FootholdMsg, MapMsg, MapUpdateMsg};

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let config = match args.next() {
        Some(path) => zenoh::Config::from_file(&path).map_err(|e| anyhow::anyhow!("{path}: {e}"))?,
        None => zenoh::Config::default(),
    };
    let prefix = args.next().unwrap_or_else(|| "polymap/leju".into());
    let session = zenoh::open(config).await.map_err(|e| anyhow::anyhow!("{e}"))?;

    // Updates: whole polygons added or changed, ids removed.
    let _updates = session
        .declare_subscriber(format!("{prefix}/map/updates"))
        .callback(|sample| match ros::decode::<MapUpdateMsg>(&sample.payload().to_bytes()) {
            Ok(u) => println!(
                "update: {} added, {} changed, {} removed; drift {:.1} mm",
                u.added.len(),
                u.changed.len(),
                u.removed.len(),
                u.drift_z * 1e3
            ),
            Err(e) => eprintln!("undecodable update: {e}"),
        })
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    tokio::time::sleep(Duration::from_secs(2)).await;

    // The whole map at once, as a planner joining late gets it.
    let replies = session.get(format!("{prefix}/map")).await.map_err(|e| anyhow::anyhow!("{e}"))?;
    while let Ok(reply) = replies.recv_async().await {
        let sample = reply.result().map_err(|e| anyhow::anyhow!("map query failed: {e:?}"))?;
        let map: MapMsg = ros::decode(&sample.payload().to_bytes()).map_err(|e| anyhow::anyhow!(e))?;
        println!("map: {} polygons", map.polygons.len());
        for p in &map.polygons {
            println!("  {:>4} {:<8} step {:>2}  area {:.3} m2  z {:.3} m", p.id, p.label, p.step, p.area, p.centroid.z);
        }
    }

    // The foothold under a point on the second tread of the mock stairs.
    let replies =
        session.get(format!("{prefix}/foothold?x=0.42;y=0.0;z=0.30")).await.map_err(|e| anyhow::anyhow!("{e}"))?;
    while let Ok(reply) = replies.recv_async().await {
        match reply.result() {
            Ok(sample) => {
                let f: FootholdMsg = ros::decode(&sample.payload().to_bytes()).map_err(|e| anyhow::anyhow!(e))?;
                println!(
                    "foothold: found {} (contains {}), polygon {} ({}), piece of {} vertices, {:.3} m away",
                    f.found,
                    f.contains,
                    f.polygon_id,
                    f.label,
                    f.piece.len(),
                    f.distance
                );
            }
            Err(e) => eprintln!("foothold query refused: {}", String::from_utf8_lossy(&e.payload().to_bytes())),
        }
    }
    Ok(())
}
