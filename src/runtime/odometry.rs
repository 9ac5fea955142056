//! VINS's odometry in: every message on the odometry topic is decoded and checked, and only
//! a good pose reaches the pose buffer. Anything bad is counted and logged (the first ten,
//! then every thousandth) and changes nothing.

use std::sync::Arc;

use parking_lot::Mutex;

use crate::interface::{Interface, OdometryTopic, convert};
use crate::pose::{PoseBuffer, RawPose};
use crate::ros2::cdr::CdrError;
use crate::ros2::{Node, Ros2Error, Subscription};

/// Feeds `buffer` from the odometry topic.
pub async fn subscribe(
    node: &Node,
    interface: &Interface,
    buffer: Arc<Mutex<PoseBuffer>>,
) -> Result<Subscription, Ros2Error> {
    let name = interface.odometry_name().to_string();
    match &interface.odometry {
        OdometryTopic::Odometry(topic) => {
            node.subscribe(topic, move |m| {
                take(&buffer, &name, m.map_err(decode_error).and_then(|m| convert::pose_of_odometry(&m)))
            })
            .await
        }
        OdometryTopic::PoseStamped(topic) => {
            node.subscribe(topic, move |m| {
                take(&buffer, &name, m.map_err(decode_error).and_then(|m| convert::pose_of_pose_stamped(&m)))
            })
            .await
        }
    }
}

fn decode_error(e: CdrError) -> String {
    format!("not a message of the topic's type: {e}")
}

/// One message's pose into the buffer, or counted out.
pub fn take(buffer: &Mutex<PoseBuffer>, topic: &str, pose: Result<RawPose, String>) {
    let mut buf = buffer.lock();
    let problem = match pose {
        Ok(raw) => buf.push(&raw).err().map(|e| e.to_string()),
        Err(e) => {
            buf.counters.undecodable += 1;
            Some(e)
        }
    };
    if let Some(why) = problem {
        let bad = buf.counters.rejected + buf.counters.undecodable;
        if bad <= 10 || bad.is_multiple_of(1000) {
            tracing::warn!("pose on {topic} refused ({bad} so far): {why}");
        }
    }
}
