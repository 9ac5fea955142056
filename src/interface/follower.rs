//! Following polymap's map from its versioned updates, as a planner should: hold the whole
//! map, apply each update that starts where the held map is, ignore what is older, and on a
//! gap (updates lost, or joining late) take a whole map (`get_map`, or the `map` topic) and
//! go on from it with the updates that came meanwhile. A whole map older than what is held
//! is ignored, so a removed polygon never comes back from a late answer.
//!
//! Pure logic, no I/O: feed it what arrives, ask for a whole map when it says so
//! (examples/planner_client.rs and tests/contract.rs show the loop).

use std::collections::BTreeMap;

use crate::ros2::msg::{Map, MapUpdate, Polygon};

/// Updates held while waiting for a whole map; older ones are dropped (the whole map covers them).
const MAX_PENDING: usize = 1024;

/// What the follower did with an update.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Followed {
    /// It started where the held map was: applied (with any held ones it let follow).
    Applied,
    /// Older than the held map (or of an earlier mapper run): ignored.
    Stale,
    /// It starts past the held map (updates were missed), or no map is held yet: kept until
    /// a whole map comes. Ask for one.
    NeedWholeMap,
}

/// How it went, for logs and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FollowerCounters {
    pub applied: u64,
    pub stale: u64,
    /// Updates that came past the held map.
    pub gaps: u64,
    pub whole_maps_taken: u64,
    pub whole_maps_ignored: u64,
}

/// The map as a planner holds it.
#[derive(Debug, Default)]
pub struct MapFollower {
    /// (mapper run, version) of the map held; None before the first whole map.
    held: Option<(u64, u64)>,
    polygons: BTreeMap<u64, Polygon>,
    drift_z: f64,
    drift_var: f64,
    frame_id: String,
    /// Updates past the held map, by the version they apply to.
    pending: BTreeMap<(u64, u64), MapUpdate>,
    pub counters: FollowerCounters,
}

impl MapFollower {
    pub fn new() -> MapFollower {
        MapFollower::default()
    }

    /// (mapper run, version) of the map held.
    pub fn version(&self) -> Option<(u64, u64)> {
        self.held
    }

    /// True while no map is held or updates past it wait: ask for a whole map.
    pub fn needs_whole_map(&self) -> bool {
        self.held.is_none() || !self.pending.is_empty()
    }

    /// The polygons held, by id.
    pub fn polygons(&self) -> impl Iterator<Item = &Polygon> {
        self.polygons.values()
    }

    /// The map held, as get_map would give it (header stamp left at zero).
    pub fn map(&self) -> Option<Map> {
        let (epoch, version) = self.held?;
        let mut m = Map {
            epoch,
            version,
            drift_z: self.drift_z,
            drift_var: self.drift_var,
            polygons: self.polygons.values().cloned().collect(),
            ..Map::default()
        };
        m.header.frame_id = self.frame_id.clone();
        Some(m)
    }

    pub fn on_update(&mut self, u: MapUpdate) -> Followed {
        let Some((epoch, version)) = self.held else {
            self.hold(u);
            return Followed::NeedWholeMap;
        };
        if u.epoch < epoch || (u.epoch == epoch && u.version <= version) {
            self.counters.stale += 1;
            return Followed::Stale;
        }
        if u.epoch == epoch && u.from_version == version {
            self.apply(u);
            self.apply_pending();
            return Followed::Applied;
        }
        // Past the held map, or a restarted mapper's: wait for a whole map.
        self.counters.gaps += 1;
        self.hold(u);
        Followed::NeedWholeMap
    }

    /// Takes a whole map unless it is older than the one held. Returns whether it did.
    pub fn on_map(&mut self, m: Map) -> bool {
        if self.held.is_some_and(|held| (m.epoch, m.version) <= held) {
            self.counters.whole_maps_ignored += 1;
            return false;
        }
        self.held = Some((m.epoch, m.version));
        self.polygons = m.polygons.into_iter().map(|p| (p.id, p)).collect();
        self.drift_z = m.drift_z;
        self.drift_var = m.drift_var;
        self.frame_id = m.header.frame_id;
        self.counters.whole_maps_taken += 1;
        self.apply_pending();
        true
    }

    fn hold(&mut self, u: MapUpdate) {
        self.pending.insert((u.epoch, u.from_version), u);
        while self.pending.len() > MAX_PENDING {
            self.pending.pop_first();
        }
    }

    fn apply(&mut self, u: MapUpdate) {
        for id in &u.removed {
            self.polygons.remove(id);
        }
        for p in u.added.into_iter().chain(u.changed) {
            self.polygons.insert(p.id, p);
        }
        self.drift_z = u.drift_z;
        self.drift_var = u.drift_var;
        self.frame_id = u.header.frame_id;
        self.held = Some((u.epoch, u.version));
        self.counters.applied += 1;
    }

    /// Applies the held updates that now follow on, drops those the map has passed.
    fn apply_pending(&mut self) {
        while let Some((epoch, version)) = self.held {
            self.pending.retain(|&(e, _), u| (e, u.version) > (epoch, version));
            match self.pending.remove(&(epoch, version)) {
                Some(next) => self.apply(next),
                None => break,
            }
        }
    }
}
