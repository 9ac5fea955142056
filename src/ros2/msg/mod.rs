//! ROS 2 message and service types: the common interfaces polymap uses, polymap_msgs, and
//! the terrain messages of existing legged planners.

mod polymap;
mod standard;
mod terrain;

pub use polymap::*;
pub use standard::*;
pub use terrain::*;
