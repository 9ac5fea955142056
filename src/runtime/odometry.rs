//! VINS's odometry in: every message on the odometry topic is decoded and checked, and only
//! a good pose reaches the pose buffer. Anything bad is counted and logged (the first ten,
//! then every thousandth) and changes nothing.

use std::sync::Arc;

use parking_lot::Mutex;

use crate::interface::{Interface, OdometryTopic, convert};
use crate::pose::{PoseBuffer, RawPose};
use crate::ros2::cdr::CdrError;
use crate::ros2::{Node, Ros2Error, Subscription};

/// Feeds `buffer` from the odometry topic (and the propagated odometry's, when used).
pub async fn subscribe(
    node: &Node,
    interface: &Interface,
    buffer: Arc<Mutex<PoseBuffer>>,
) -> Result<Vec<Subscription>, Ros2Error> {
    let name = interface.odometry_name().to_string();
    let optimised = buffer.clone();
    let mut subscriptions = vec![match &interface.odometry {
        OdometryTopic::Odometry(topic) => {
            node.subscribe(topic, move |m| {
                let pose = m.map_err(decode_error).and_then(|m| convert::pose_of_odometry(&m));
                take(&optimised, &name, Stream::Optimised, pose)
            })
            .await?
        }
        OdometryTopic::PoseStamped(topic) => {
            node.subscribe(topic, move |m| {
                let pose = m.map_err(decode_error).and_then(|m| convert::pose_of_pose_stamped(&m));
                take(&optimised, &name, Stream::Optimised, pose)
            })
            .await?
        }
    }];
    if let Some(topic) = &interface.imu_propagate {
        let name = topic.name.to_string();
        subscriptions.push(
            node.subscribe(topic, move |m| {
                let pose = m.map_err(decode_error).and_then(|m| convert::pose_of_odometry(&m));
                take(&buffer, &name, Stream::Propagated, pose)
            })
            .await?,
        );
    }
    Ok(subscriptions)
}

/// Which of VINS's streams a pose came on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// The optimised odometry.
    Optimised,
    /// The IMU-rate propagated odometry.
    Propagated,
}

fn decode_error(e: CdrError) -> String {
    format!("not a message of the topic's type: {e}")
}

/// One message's pose into the buffer, or counted out.
pub fn take(buffer: &Mutex<PoseBuffer>, topic: &str, stream: Stream, pose: Result<RawPose, String>) {
    let mut buf = buffer.lock();
    let now = crate::clock::now_ns();
    let problem = match pose {
        Ok(raw) => match stream {
            Stream::Optimised => buf.push_at(&raw, now),
            Stream::Propagated => buf.push_propagated_at(&raw, now),
        }
        .err()
        .map(|e| e.to_string()),
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
