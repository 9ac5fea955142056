//! ROS 2 message and service types: the common interfaces polymap uses, and polymap_msgs.

mod polymap;
mod standard;

pub use polymap::*;
pub use standard::*;
