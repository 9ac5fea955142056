//! `polymap router`: a Zenoh router in a process of its own, as rmw_zenohd is to ROS 2: the
//! robot's processes and remote planners connect to it rather than to each other
//! (config/zenoh/robot/router.json5 makes it the robot's, with mutual TLS and access
//! control). For a machine with no zenohd or rmw_zenohd at hand, and for the tests.

use std::time::Duration;

use anyhow::{Result, anyhow};

/// Routes until SIGINT / SIGTERM or `duration`. The config file's mode is set to router.
pub async fn run(config_file: &std::path::Path, duration: Option<Duration>) -> Result<()> {
    let mut config = crate::ros2::session::config(config_file)?;
    config.insert_json5("mode", r#""router""#).map_err(|e| anyhow!("zenoh config: {e}"))?;
    let session = crate::ros2::session::open(config).await?;
    tracing::info!("Zenoh router {} up", session.zid());
    let mut signals = super::StopSignals::new()?;
    let deadline = async {
        match duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::select! {
        _ = deadline => {}
        _ = signals.recv() => {}
    }
    session.close().await.map_err(|e| anyhow!("closing the router: {e}"))
}
