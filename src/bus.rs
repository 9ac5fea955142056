//! Zenoh: opening a session from the config, and the pose subscriber that feeds the pose
//! buffer. Whatever arrives on the pose key is decoded and checked; anything bad is counted
//! and logged (the first few, then every thousandth) and never reaches the buffer.

use std::sync::{Arc, Mutex};

use anyhow::{Result, anyhow};

use crate::config::ZenohConfig;
use crate::pose::PoseBuffer;
use crate::ros::decode_pose;

/// A Zenoh session: the config's JSON5 file, or a peer with Zenoh's defaults.
pub async fn open_session(cfg: &ZenohConfig) -> Result<zenoh::Session> {
    let config = if cfg.config_file.as_os_str().is_empty() {
        zenoh::Config::default()
    } else {
        zenoh::Config::from_file(&cfg.config_file)
            .map_err(|e| anyhow!("zenoh config {}: {e}", cfg.config_file.display()))?
    };
    zenoh::open(config).await.map_err(|e| anyhow!("opening the zenoh session: {e}"))
}

/// Feeds `buffer` from every message on `key` (a key expression; wildcards allowed).
pub async fn subscribe_poses(
    session: &zenoh::Session,
    key: &str,
    buffer: Arc<Mutex<PoseBuffer>>,
) -> Result<zenoh::pubsub::Subscriber<()>> {
    let key_owned = key.to_string();
    session
        .declare_subscriber(key)
        .callback(move |sample| {
            let bytes = sample.payload().to_bytes();
            let decoded = decode_pose(sample.key_expr().as_str(), &bytes);
            let mut buf = buffer.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            let problem = match decoded {
                Ok(raw) => buf.push(&raw).err().map(|e| e.to_string()),
                Err(e) => {
                    buf.counters.undecodable += 1;
                    Some(e)
                }
            };
            if let Some(why) = problem {
                let bad = buf.counters.rejected + buf.counters.undecodable;
                if bad <= 10 || bad % 1000 == 0 {
                    tracing::warn!("pose on {key_owned} refused ({bad} so far): {why}");
                }
            }
        })
        .await
        .map_err(|e| anyhow!("subscribing to poses on {key}: {e}"))
}
