//! polymap's services: the whole map, and the foothold under a point. A request that does
//! not decode is refused with the reason and counted.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use parking_lot::Mutex;

use super::status::Counters;
use crate::clock::now_ns;
use crate::interface::convert;
use crate::interface::wires::{Held, WireError, Wires};
use crate::map::PolygonMap;
use crate::ros2::msg::{GetFootholdResponse, GetMapResponse};

/// Serves `get_map` and `get_foothold` on every ROS layer until the servers are dropped. The
/// map is taken whole under its lock when the request comes, so its version is what it holds.
pub async fn serve(
    wires: &Wires,
    map: Arc<Mutex<PolygonMap>>,
    counters: Arc<Counters>,
    epoch: u64,
    map_frame: &str,
) -> Result<Vec<Held>, WireError> {
    let refused = |counters: &Counters, service: &str, why: &dyn std::fmt::Display| {
        let n = counters.requests_refused.fetch_add(1, Ordering::Relaxed) + 1;
        if n <= 10 || n.is_multiple_of(1000) {
            tracing::warn!("{service}: request refused ({n} so far): {why}");
        }
        format!("{service}: the request does not decode: {why}")
    };
    let get_map = {
        let (map, counters, name) = (map.clone(), counters.clone(), "get_map");
        let frame = map_frame.to_string();
        wires
            .serve(
                |i| &i.get_map,
                move |request| match request {
                    Ok(_) => {
                        let snapshot = map.lock().snapshot();
                        Ok(GetMapResponse { map: convert::map(&snapshot, now_ns(), epoch, &frame) })
                    }
                    Err(e) => Err(refused(&counters, name, &e)),
                },
            )
            .await?
    };
    let get_foothold = {
        let name = "get_foothold";
        let frame = map_frame.to_string();
        wires
            .serve(
                |i| &i.get_foothold,
                move |request| {
                    let point = match request {
                        Ok(r) => r.point,
                        Err(e) => return Err(refused(&counters, name, &e)),
                    };
                    let p = [point.x, point.y, point.z];
                    if !p.iter().all(|v| v.is_finite()) {
                        return Err(refused(&counters, name, &format!("the point {p:?} is not finite")));
                    }
                    let snapshot = map.lock().snapshot();
                    let found = crate::map::foothold::foothold(&snapshot, p);
                    Ok(GetFootholdResponse { foothold: convert::foothold(&found, now_ns(), &frame) })
                },
            )
            .await?
    };
    Ok(get_map.into_iter().chain(get_foothold).collect())
}
