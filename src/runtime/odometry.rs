//! VINS's odometry in: every message on the odometry topic is decoded and checked, and only
//! a good pose reaches the pose buffer. Anything bad is counted and logged (the first ten,
//! then every thousandth) and changes nothing.

use std::sync::Arc;

use parking_lot::Mutex;

use crate::interface::wires::{Held, WireError, Wires};
use crate::interface::{OdometryTopic, convert};
use crate::pose::{PoseBuffer, RawPose};
use crate::ros2::cdr::CdrError;

/// Feeds `buffer` from the odometry topic (and the propagated odometry's, when used), on
/// every ROS layer the mapper speaks.
pub async fn subscribe(wires: &Wires, buffer: Arc<Mutex<PoseBuffer>>) -> Result<Vec<Held>, WireError> {
    let into = |stream: Stream| {
        let buffer = buffer.clone();
        move |topic: &str, pose: Result<RawPose, String>| take(&buffer, topic, stream, pose)
    };
    let (optimised, pose_stamped, propagated) =
        (into(Stream::Optimised), into(Stream::Optimised), into(Stream::Propagated));
    let mut held = wires
        .subscribe(
            |i| match &i.odometry {
                OdometryTopic::Odometry(t) => Some(t),
                OdometryTopic::PoseStamped(_) => None,
            },
            move |topic, m| optimised(topic, m.map_err(decode_error).and_then(|m| convert::pose_of_odometry(&m))),
        )
        .await?;
    held.extend(
        wires
            .subscribe(
                |i| match &i.odometry {
                    OdometryTopic::PoseStamped(t) => Some(t),
                    OdometryTopic::Odometry(_) => None,
                },
                move |topic, m| {
                    pose_stamped(topic, m.map_err(decode_error).and_then(|m| convert::pose_of_pose_stamped(&m)))
                },
            )
            .await?,
    );
    held.extend(
        wires
            .subscribe(
                |i| i.imu_propagate.as_ref(),
                move |topic, m| propagated(topic, m.map_err(decode_error).and_then(|m| convert::pose_of_odometry(&m))),
            )
            .await?,
    );
    Ok(held)
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
