//! ROS 1 (Noetic), natively: a node registered with the robot's rosmaster, so rospy and
//! roscpp nodes (VINS-Fusion, the planners) see polymap's topics and services as any other
//! node's, and polymap takes VINS's odometry from them. It runs beside the ROS 2 layer.
//!
//! - [`xmlrpc`]: XML-RPC over HTTP, to the master and from peers;
//! - [`tcpros`]: TCPROS connection headers and framing;
//! - [`types`], [`msg`]: message and service types, their MD5 sums and definitions;
//! - [`node`]: a node, its publishers, subscriptions and services.
//!
//! polymap's own protocol code rather than roslibrust's or rosrust's: both trust the length
//! prefixes a peer sends (4 bytes can reserve 4 GiB) and panic on peers that break off a
//! handshake, and neither can count what it refused (docs/ros1.md).

pub mod msg;
pub mod node;
pub mod tcpros;
pub mod types;
pub mod xmlrpc;

pub use node::{Node, Publisher};
pub use types::{Ros1Message, Ros1Service};

/// Set when a peer's message or call over [`LARGE_READ_BYTES`] was read: the node gives the
/// memory back a while after the last of them.
static LARGE_READS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
const LARGE_READ_BYTES: usize = 64 * 1024;

/// Notes a read of `len` bytes from a peer.
fn note_read(len: usize) {
    if len > LARGE_READ_BYTES {
        LARGE_READS.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// Where rospy looks for the master when `ROS_MASTER_URI` is not set.
pub const DEFAULT_MASTER_URI: &str = "http://localhost:11311/";

/// Where the master is and who this node is, as roscpp reads them from the environment.
#[derive(Clone, Debug)]
pub struct NodeOptions {
    /// `ROS_MASTER_URI`, e.g. `http://localhost:11311/` ([`DEFAULT_MASTER_URI`] when unset).
    pub master_uri: String,
    /// The node's fully qualified name, e.g. `/polymap`.
    pub name: String,
    /// The name or address peers reach this node at: `ROS_HOSTNAME`, else `ROS_IP`, else
    /// the machine's host name.
    pub host: String,
}

impl NodeOptions {
    /// From `ROS_MASTER_URI`, `ROS_HOSTNAME` and `ROS_IP`, as rospy takes them.
    pub fn from_env(name: &str) -> Result<NodeOptions, Ros1Error> {
        let var = |k: &str| std::env::var(k).ok().filter(|v| !v.trim().is_empty());
        // rospy's default when it is not set: the master on this machine.
        let master_uri = var("ROS_MASTER_URI").unwrap_or_else(|| DEFAULT_MASTER_URI.to_string());
        xmlrpc::host_port(&master_uri)
            .map_err(|e| Ros1Error::Config { what: "ROS_MASTER_URI".into(), why: e.to_string() })?;
        let host = match var("ROS_HOSTNAME").or_else(|| var("ROS_IP")) {
            Some(h) => h,
            None => hostname()?,
        };
        Ok(NodeOptions { master_uri, name: name.to_string(), host })
    }

    /// Whether peers reach this node on the loopback only (then it listens there only).
    pub fn host_is_loopback(&self) -> bool {
        self.host == "localhost" || self.host.starts_with("127.")
    }
}

fn hostname() -> Result<String, Ros1Error> {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most buf.len() bytes into buf.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if rc != 0 {
        return Err(Ros1Error::Config {
            what: "the host name".into(),
            why: format!("{}; set ROS_HOSTNAME or ROS_IP", std::io::Error::last_os_error()),
        });
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    Ok(String::from_utf8_lossy(&buf[..end]).into_owned())
}

#[derive(Debug, thiserror::Error)]
pub enum Ros1Error {
    #[error("ROS 1 master at {uri}: {why}")]
    Master { uri: String, why: String },
    #[error("ROS 1: {what} {why}")]
    Config { what: String, why: String },
    #[error("ROS 1 peer: {0}")]
    Peer(String),
    #[error("{0}")]
    XmlRpc(#[from] xmlrpc::XmlRpcError),
    #[error("TCPROS: {0}")]
    Tcpros(#[from] tcpros::TcprosError),
    #[error("{0}")]
    Io(#[from] std::io::Error),
}
