//! Quality of service, as a ROS 2 publisher or subscriber declares it, and how each wire
//! convention writes it into its liveliness tokens.

/// The QoS policies that matter on Zenoh (deadline, lifespan and liveliness stay at ROS 2's
/// defaults, which is what every polymap topic uses).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Qos {
    pub reliability: Reliability,
    pub durability: Durability,
    pub history: History,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reliability {
    Reliable,
    BestEffort,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Durability {
    Volatile,
    /// Late joiners get the last `depth` samples (rmw_zenoh: zenoh-ext's advanced publisher cache).
    TransientLocal,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum History {
    KeepLast(u32),
    KeepAll,
}

/// rmw_zenoh's default depth, written as empty in its tokens.
const RMW_ZENOH_DEFAULT_DEPTH: u32 = 42;

impl Qos {
    /// rclcpp's `QoS(depth)`: reliable, volatile, keep last `depth`.
    pub const fn reliable(depth: u32) -> Qos {
        Qos { reliability: Reliability::Reliable, durability: Durability::Volatile, history: History::KeepLast(depth) }
    }

    /// Reliable, and nothing dropped on congestion: the publisher waits (keep all).
    pub const fn every_sample() -> Qos {
        Qos { reliability: Reliability::Reliable, durability: Durability::Volatile, history: History::KeepAll }
    }

    /// Reliable, transient local, keep last `depth`: a late subscriber gets the last samples.
    pub const fn latched(depth: u32) -> Qos {
        Qos {
            reliability: Reliability::Reliable,
            durability: Durability::TransientLocal,
            history: History::KeepLast(depth),
        }
    }

    /// The depth a cache or queue keeps.
    /// Whether a late subscriber gets the last samples (ROS 1's latching).
    pub fn is_latched(&self) -> bool {
        self.durability == Durability::TransientLocal
    }

    pub fn depth(&self) -> u32 {
        match self.history {
            History::KeepLast(0) | History::KeepAll => RMW_ZENOH_DEFAULT_DEPTH,
            History::KeepLast(n) => n,
        }
    }

    /// rmw_zenoh's token form, `<rel>:<dur>:<hist>,<depth>:<deadline>:<lifespan>:<liveliness>`,
    /// each field empty where it is rmw_zenoh's default (reliable, volatile, keep last 42,
    /// infinite durations, automatic liveliness).
    pub fn rmw_zenoh_key(&self) -> String {
        let rel = match self.reliability {
            Reliability::Reliable => "",
            Reliability::BestEffort => "2",
        };
        let dur = match self.durability {
            Durability::Volatile => "",
            Durability::TransientLocal => "1",
        };
        let (hist, depth) = match self.history {
            History::KeepAll => ("2", RMW_ZENOH_DEFAULT_DEPTH),
            History::KeepLast(_) => ("", self.depth()),
        };
        let depth = if depth == RMW_ZENOH_DEFAULT_DEPTH { String::new() } else { depth.to_string() };
        format!("{rel}:{dur}:{hist},{depth}:,:,:,,")
    }

    /// zenoh-bridge-ros2dds's token form, `:<rel>:<dur>:<hist>,<depth>[:<user data>]` with DDS's
    /// numbers (a ROS topic is keyless: no leading `K`).
    pub fn bridge_key(&self, type_hash: Option<&str>) -> String {
        let rel = match self.reliability {
            Reliability::BestEffort => 0,
            Reliability::Reliable => 1,
        };
        let dur = match self.durability {
            Durability::Volatile => 0,
            Durability::TransientLocal => 1,
        };
        let (hist, depth) = match self.history {
            History::KeepLast(n) => (0, n),
            History::KeepAll => (1, 0),
        };
        // From Iron on, ROS 2 puts its type hash in the DDS USER_DATA, and the bridge forwards it.
        let user_data = type_hash.map(|h| format!(":typehash={h};")).unwrap_or_default();
        format!(":{rel}:{dur}:{hist},{depth}{user_data}")
    }
}
