//! Where ROS 2 entities meet on Zenoh: the key a topic's or service's data goes on, and the
//! liveliness token that announces a node, publisher, subscription or service, in each wire
//! convention. Pure functions of names, so tests hold them to the formats the peers define.
//!
//! - rmw_zenoh (its docs/design.md, and liveliness_utils.cpp as released for Jazzy 0.2.10
//!   and Humble 0.1.9): data on `<domain>/<name without its leading '/'>/<pkg>::msg::dds_::<Type>_/<hash>`,
//!   tokens `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>`
//!   and for entities `/<name>/<type>/<hash>/<qos>`, each name with its `/` written `%`.
//!   Humble has no type hashes: `TypeHashNotSupported` stands where the hash goes.
//! - zenoh-bridge-ros2dds (its liveliness_mgt.rs, 1.10): data on the ROS name without its
//!   leading `/`; tokens `@/<zid>/@ros2_lv/<kind>/<key>/<type>[/<qos>]` with the key's and the
//!   type's `/` written `§`.

use super::names::RosName;
use super::{Distro, Mode};

/// What a liveliness token announces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EntityKind {
    Node,
    Publisher,
    Subscription,
    ServiceServer,
    ServiceClient,
}

impl EntityKind {
    fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
            EntityKind::ServiceServer => "SS",
            EntityKind::ServiceClient => "SC",
        }
    }
}

/// rmw_zenoh's stand-in for a hash on distros without type hashes.
pub const NO_TYPE_HASH: &str = "TypeHashNotSupported";

/// A topic or service as the wire sees it.
#[derive(Clone, Debug)]
pub struct Endpoint<'a> {
    pub name: &'a RosName,
    /// `pkg/msg/Name` or `pkg/srv/Name`.
    pub type_name: &'a str,
    /// RIHS01 hash of the type.
    pub type_hash: &'a str,
}

/// The Zenoh key a topic's or service's data goes on.
pub fn data_key(mode: Mode, domain: u32, e: &Endpoint) -> String {
    match mode {
        Mode::RmwZenoh(distro) => {
            format!(
                "{domain}/{}/{}/{}",
                e.name.stripped(),
                super::types::dds_type_name(e.type_name),
                hash_field(distro, e)
            )
        }
        Mode::Bridge => e.name.stripped().to_string(),
    }
}

fn hash_field<'a>(distro: Distro, e: &Endpoint<'a>) -> &'a str {
    match distro {
        Distro::Humble => NO_TYPE_HASH,
        Distro::Jazzy => e.type_hash,
    }
}

/// The node a token belongs to.
#[derive(Clone, Debug)]
pub struct NodeId<'a> {
    pub domain: u32,
    /// The Zenoh session id, as `ZenohId`'s Display writes it.
    pub zid: &'a str,
    pub id: u32,
    pub namespace: &'a RosName,
    pub name: &'a str,
}

/// rmw_zenoh's token for the node itself (`entity` None) or one of its entities.
pub fn rmw_zenoh_token(distro: Distro, node: &NodeId, entity: Option<(u32, EntityKind, &Endpoint, &str)>) -> String {
    // rcl's default enclave is "/", written "%".
    let namespace = if node.namespace.as_str() == "/" { "%".to_string() } else { node.namespace.mangled() };
    let (id, kind) = entity.map_or((node.id, EntityKind::Node), |(id, kind, _, _)| (id, kind));
    let mut token =
        format!("@ros2_lv/{}/{}/{}/{id}/{}/%/{namespace}/{}", node.domain, node.zid, node.id, kind.code(), node.name);
    if let Some((_, _, e, qos)) = entity {
        token.push_str(&format!(
            "/{}/{}/{}/{qos}",
            e.name.mangled(),
            super::types::dds_type_name(e.type_name),
            hash_field(distro, e)
        ));
    }
    token
}

/// zenoh-bridge-ros2dds's announcement of an entity (`qos` for publishers and subscriptions).
pub fn bridge_token(zid: &str, kind: EntityKind, e: &Endpoint, qos: Option<&str>) -> String {
    const SLASH: &str = "§";
    let key = e.name.stripped().replace('/', SLASH);
    let ty = e.type_name.replace('/', SLASH);
    match qos {
        Some(q) => format!("@/{zid}/@ros2_lv/{}/{key}/{ty}/{q}", kind.code()),
        None => format!("@/{zid}/@ros2_lv/{}/{key}/{ty}", kind.code()),
    }
}
