//! `polymap demo`: the whole loop on one machine. A Zenoh router listens where ROS 2 nodes
//! and the README's clients expect one (tcp/127.0.0.1:7447, when that port is free; it says
//! where it listens), and the mock VINS and the mapper are its peers: rmw_zenoh nodes learn
//! of each other through a router, so a ROS 2 node attached to the demo sees every node. With
//! `[ros1] enabled` both also register with the rosmaster, and the mock VINS speaks ROS 1.

use std::time::Duration;

use anyhow::Result;

use super::status::Report;
use crate::config::Config;
use crate::mock::vins::MockVinsOptions;
use crate::ros2::session::{free_loopback_port, loopback, loopback_json5};
use crate::sequence::Sequence;

/// The port rmw_zenoh's router listens on, where clients look first.
pub const ROUTER_PORT: u16 = 7447;

/// Runs for `duration`; the map is saved where `config.map.snapshot_path` says.
pub async fn demo(config: &Config, duration: Duration, vins: MockVinsOptions) -> Result<Report> {
    let opts = MockVinsOptions { duration: None, ..vins };
    if let Some(p) = opts.problem() {
        anyhow::bail!("{}", p.replace("--", "--vins-"));
    }
    let port = if std::net::TcpListener::bind(("127.0.0.1", ROUTER_PORT)).is_ok() {
        ROUTER_PORT
    } else {
        free_loopback_port()?
    };
    let dir = tempfile::tempdir()?;
    let write = |name: &str, text: String| -> Result<std::path::PathBuf> {
        let path = dir.path().join(name);
        std::fs::write(&path, text)?;
        Ok(path)
    };
    let mut router = loopback(Some(port), &[]);
    router.insert_json5("mode", r#""router""#).map_err(|e| anyhow::anyhow!("zenoh config: {e}"))?;
    let _router = crate::ros2::session::open(router).await?;
    let mut mapper = config.clone();
    mapper.zenoh.config_file = write("mapper.json5", loopback_json5(None, &[port]))?;
    let mut vins = config.clone();
    vins.zenoh.config_file = write("vins.json5", loopback_json5(None, &[port]))?;
    println!("polymap demo: clients connect to tcp/127.0.0.1:{port} (ROS 2 namespace {})", config.ros2.namespace);
    if config.ros1.enabled {
        println!("polymap demo: on ROS 1 as {}, VINS as /vins_estimator", config.ros1.node);
    }
    let seq = Sequence::open(&config.sources.depth.sequence)?;
    let vins_task = tokio::spawn(async move { crate::mock::vins::run(&seq, &vins, opts).await });
    let summary = super::run(&mapper, Some(duration)).await;
    if vins_task.is_finished() {
        // The mock VINS only ends by failing: the demo mapped without poses.
        if let Ok(Err(e)) = vins_task.await {
            anyhow::bail!("the mock VINS failed: {e:#}");
        }
    } else {
        vins_task.abort();
    }
    summary
}
