//! ROS 2 on Zenoh, natively: polymap's topics and services are what a ROS 2 node on
//! rmw_zenoh (ROS 2's Zenoh middleware) or behind zenoh-bridge-ros2dds sees as any other
//! node's, and it takes VINS's odometry the same way.
//!
//! - [`cdr`]: ROS 2's CDR, decoding bounded by the bytes it reads;
//! - [`types`], [`msg`]: message and service types, with their type hashes (REP 2016);
//! - [`names`], [`graph`], [`qos`], [`attachment`]: ROS names, the keys and liveliness tokens
//!   each convention makes of them, QoS in those tokens, rmw_zenoh's sample attachments;
//! - [`node`]: a node, its publishers, subscriptions, services and clients;
//! - [`session`]: opening the Zenoh session as Zenoh and rmw_zenoh users expect.
//!
//! Written from rmw_zenoh's design document and sources (not on hiroz, which forces zenoh's
//! transports, shared memory and a session of its own on its users).

pub mod attachment;
pub mod cdr;
pub mod graph;
pub mod msg;
pub mod names;
pub mod node;
pub mod qos;
pub mod session;
pub mod types;

use std::marker::PhantomData;

use serde::{Deserialize, Serialize};

pub use names::RosName;
pub use node::{Client, Node, NodeOptions, Publisher, ServiceServer, Subscription};
pub use qos::Qos;

/// Which ROS 2 conventions the wire follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// rmw_zenoh: typed keys, attachments, `@ros2_lv` liveliness tokens, complete queryables.
    RmwZenoh(Distro),
    /// Next to a zenoh-bridge-ros2dds: keys are ROS names, announced as the bridge announces.
    Bridge,
}

/// The ROS 2 release rmw_zenoh's formats follow: keys carry type hashes from Jazzy on (Kilted
/// and Rolling write them as Jazzy does); Humble's carry none.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Distro {
    Jazzy,
    Humble,
}

/// How published samples are encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// ROS 2 CDR, what ROS 2 nodes read.
    Cdr,
    /// JSON, for looking at the messages with plain Zenoh tools (ROS 2 nodes cannot read it).
    Json,
}

/// A topic: its fully qualified name, message type and QoS.
#[derive(Debug)]
pub struct Topic<T> {
    pub name: RosName,
    pub qos: Qos,
    _type: PhantomData<fn() -> T>,
}

impl<T> Topic<T> {
    pub fn new(name: RosName, qos: Qos) -> Topic<T> {
        Topic { name, qos, _type: PhantomData }
    }
}

impl<T> Clone for Topic<T> {
    fn clone(&self) -> Self {
        Topic::new(self.name.clone(), self.qos)
    }
}

/// A service: its fully qualified name and service type.
#[derive(Debug)]
pub struct Service<S> {
    pub name: RosName,
    _type: PhantomData<fn() -> S>,
}

impl<S> Service<S> {
    pub fn new(name: RosName) -> Service<S> {
        Service { name, _type: PhantomData }
    }
}

impl<S> Clone for Service<S> {
    fn clone(&self) -> Self {
        Service::new(self.name.clone())
    }
}

/// What went wrong on the wire.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    #[error("zenoh: {what}: {why}")]
    Zenoh { what: String, why: String },
    #[error("{0}")]
    Cdr(#[from] cdr::CdrError),
    #[error("{service}: {why}")]
    Call { service: String, why: String },
}

impl Ros2Error {
    fn zenoh(what: impl Into<String>, why: impl std::fmt::Display) -> Ros2Error {
        Ros2Error::Zenoh { what: what.into(), why: why.to_string() }
    }
}
