//! The ROS layers a process speaks at once: the mapper ROS 2 on Zenoh always and ROS 1
//! beside it when `[ros1] enabled`; the mock VINS one or the other. Each message is built
//! once and goes out on every layer; odometry and service requests are taken from every
//! layer, through the same handlers.

use std::sync::Arc;

use super::Interface;
use crate::config::Config;
use crate::ros1::{self, Ros1Error, Ros1Message, Ros1Service};
use crate::ros2::cdr::CdrError;
use crate::ros2::types::{RosMessage, RosService};
use crate::ros2::{self, Ros2Error, Service, Topic};

#[derive(Debug, thiserror::Error)]
pub enum WireError {
    #[error(transparent)]
    Ros2(#[from] Ros2Error),
    #[error(transparent)]
    Ros1(#[from] Ros1Error),
}

/// The nodes, each with its names for polymap's topics and services.
pub struct Wires {
    pub ros2: Option<(Arc<ros2::Node>, Interface)>,
    pub ros1: Option<(Arc<ros1::Node>, Interface)>,
}

/// A topic's publisher on each layer that has the topic.
pub struct Out<T> {
    ros2: Option<ros2::Publisher<T>>,
    ros1: Option<ros1::Publisher<T>>,
}

impl<T: RosMessage + Ros1Message> Out<T> {
    /// Whether any layer has this topic (so the message is worth building).
    pub fn wanted(&self) -> bool {
        self.ros2.is_some() || self.ros1.is_some()
    }

    pub async fn put(&self, msg: &T) -> Result<(), WireError> {
        if let Some(p) = &self.ros1 {
            p.put(msg);
        }
        if let Some(p) = &self.ros2 {
            p.put(msg).await?;
        }
        Ok(())
    }
}

/// What keeps a subscription or a service alive.
pub type Held = Box<dyn std::any::Any + Send + Sync>;

impl Wires {
    /// ROS 2's node with its names.
    pub fn ros2(config: &Config, node: Arc<ros2::Node>) -> (Arc<ros2::Node>, Interface) {
        (node, Interface::new(config))
    }

    /// A ROS 1 node called `name`, registered with the master `ROS_MASTER_URI` names.
    pub async fn ros1(config: &Config, name: &str) -> Result<(Arc<ros1::Node>, Interface), WireError> {
        let node = ros1::Node::new(ros1::NodeOptions::from_env(name)?).await?;
        tracing::info!("{name} on ROS 1 (master {})", node.master_uri());
        Ok((Arc::new(node), Interface::ros1(config)))
    }

    /// The topic `pick` chooses from each layer's names, where that layer has it.
    pub async fn publisher<T: RosMessage + Ros1Message>(
        &self,
        pick: impl Fn(&Interface) -> Option<&Topic<T>>,
    ) -> Result<Out<T>, WireError> {
        let mut out = Out { ros2: None, ros1: None };
        if let Some((node, names)) = &self.ros2
            && let Some(topic) = pick(names)
        {
            out.ros2 = Some(node.publisher(topic).await?);
        }
        if let Some((node, names)) = &self.ros1
            && let Some(topic) = pick(names)
        {
            out.ros1 = Some(node.publisher(topic).await?);
        }
        Ok(out)
    }

    /// Every message (or why it is not one) on the topic `pick` chooses, from either layer,
    /// with the name of the topic it came on.
    pub async fn subscribe<T: RosMessage + Ros1Message>(
        &self,
        pick: impl Fn(&Interface) -> Option<&Topic<T>>,
        on: impl Fn(&str, Result<T, CdrError>) + Send + Sync + 'static,
    ) -> Result<Vec<Held>, WireError> {
        let on = Arc::new(on);
        let mut held: Vec<Held> = Vec::new();
        if let Some((node, names)) = &self.ros2
            && let Some(topic) = pick(names)
        {
            let (on, name) = (on.clone(), topic.name.to_string());
            held.push(Box::new(node.subscribe(topic, move |m| on(&name, m)).await?));
        }
        if let Some((node, names)) = &self.ros1
            && let Some(topic) = pick(names)
        {
            let name = topic.name.to_string();
            node.subscribe(topic, move |m| on(&name, m)).await?;
        }
        Ok(held)
    }

    /// Serves the service `pick` chooses on both layers with one handler.
    pub async fn serve<S>(
        &self,
        pick: impl Fn(&Interface) -> &Service<S>,
        handler: impl Fn(Result<<S as RosService>::Request, CdrError>) -> Result<<S as RosService>::Response, String>
        + Send
        + Sync
        + 'static,
    ) -> Result<Vec<Held>, WireError>
    where
        S: RosService + Ros1Service<Request = <S as RosService>::Request, Response = <S as RosService>::Response>,
        <S as RosService>::Request: Ros1Message,
        <S as RosService>::Response: Ros1Message,
    {
        let handler = Arc::new(handler);
        let mut held: Vec<Held> = Vec::new();
        if let Some((node, names)) = &self.ros2 {
            let on = handler.clone();
            held.push(Box::new(node.serve(pick(names), move |r| on(r)).await?));
        }
        if let Some((node, names)) = &self.ros1 {
            node.serve(pick(names), move |r| handler(r)).await?;
        }
        Ok(held)
    }

    /// The names of the first layer (ROS 2's when there is one): for what the logs say.
    pub fn names(&self) -> Option<&Interface> {
        match (&self.ros2, &self.ros1) {
            (Some((_, names)), _) | (None, Some((_, names))) => Some(names),
            (None, None) => None,
        }
    }

    /// Peer connections and calls the ROS 1 node refused.
    pub fn ros1_refused(&self) -> u64 {
        self.ros1.as_ref().map_or(0, |(node, _)| node.refused())
    }
}
