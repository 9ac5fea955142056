//! polymap's services: the whole map, and the foothold under a point. A request that does
//! not decode is refused with the reason and counted.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use parking_lot::Mutex;

use super::status::Counters;
use crate::clock::now_ns;
use crate::interface::{Interface, convert};
use crate::map::PolygonMap;
use crate::ros2::msg::{GetFootholdResponse, GetMapResponse};
use crate::ros2::{Node, Ros2Error, ServiceServer};

/// Serves `get_map` and `get_foothold` until the servers are dropped. The map is taken
/// whole under its lock when the request comes, so its version is what it holds.
pub async fn serve(
    node: &Node,
    interface: &Interface,
    map: Arc<Mutex<PolygonMap>>,
    counters: Arc<Counters>,
    epoch: u64,
    map_frame: &str,
) -> Result<[ServiceServer; 2], Ros2Error> {
    let refused = |counters: &Counters, service: &str, why: &dyn std::fmt::Display| {
        let n = counters.requests_refused.fetch_add(1, Ordering::Relaxed) + 1;
        if n <= 10 || n.is_multiple_of(1000) {
            tracing::warn!("{service}: request refused ({n} so far): {why}");
        }
        format!("{service}: the request does not decode: {why}")
    };
    let get_map = {
        let (map, counters, name) = (map.clone(), counters.clone(), interface.get_map.name.to_string());
        let frame = map_frame.to_string();
        node.serve(&interface.get_map, move |request| match request {
            Ok(_) => {
                let snapshot = map.lock().snapshot();
                Ok(GetMapResponse { map: convert::map(&snapshot, now_ns(), epoch, &frame) })
            }
            Err(e) => Err(refused(&counters, &name, &e)),
        })
        .await?
    };
    let get_foothold = {
        let name = interface.get_foothold.name.to_string();
        let frame = map_frame.to_string();
        node.serve(&interface.get_foothold, move |request| {
            let point = match request {
                Ok(r) => r.point,
                Err(e) => return Err(refused(&counters, &name, &e)),
            };
            let p = [point.x, point.y, point.z];
            if !p.iter().all(|v| v.is_finite()) {
                return Err(refused(&counters, &name, &format!("the point {p:?} is not finite")));
            }
            let snapshot = map.lock().snapshot();
            let found = crate::map::foothold::foothold(&snapshot, p);
            Ok(GetFootholdResponse { foothold: convert::foothold(&found, now_ns(), &frame) })
        })
        .await?
    };
    Ok([get_map, get_foothold])
}
