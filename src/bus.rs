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

/// Publishes the D435i's samples (real or mock, the same way) as realsense-ros does:
/// `<prefix>/infra{1,2}/image_rect_raw` (sensor_msgs/Image, mono8),
/// `<prefix>/infra{1,2}/camera_info` and `<prefix>/imu` (sensor_msgs/Imu, united), ROS 2 CDR.
/// Returns how many samples went out once the sender side closes.
pub async fn publish_d435i(
    session: &zenoh::Session,
    cfg: &crate::config::D435iConfig,
    mut samples: tokio::sync::mpsc::Receiver<crate::camera::D435iSample>,
) -> Result<u64> {
    use crate::camera::D435iSample;
    use crate::camera::mock_d435i::BASELINE_M;
    use crate::ros;
    let put = |key: String, bytes: Vec<u8>| async move {
        session.put(&key, bytes).await.map_err(|e| anyhow!("publishing on {key}: {e}"))
    };
    let prefix = &cfg.key_prefix;
    let mut sent = 0;
    while let Some(sample) = samples.recv().await {
        match sample {
            D435iSample::Infrared { index, stamp_ns, intrinsics, pixels } => {
                let info = ros::ir_camera_info(stamp_ns, index, &intrinsics, BASELINE_M);
                let image = ros::ir_image(stamp_ns, index, &intrinsics, pixels);
                put(format!("{prefix}/infra{index}/camera_info"), ros::encode(&info)).await?;
                put(format!("{prefix}/infra{index}/image_rect_raw"), ros::encode(&image)).await?;
            }
            D435iSample::Imu(s) => {
                let msg = ros::imu(&s, cfg.angular_velocity_cov, cfg.linear_accel_cov);
                put(format!("{prefix}/imu"), ros::encode(&msg)).await?
            }
        }
        sent += 1;
    }
    Ok(sent)
}
