//! The mocks that stand in for hardware and for VINS, side by side, on one shared clock:
//!
//! - [`clock`]: the looped sequence's clock they share;
//! - [`depth`]: the L515, replaying a sequence's depth frames;
//! - [`d435i`]: the D435i, IR pair and IMU along the sequence's trajectory;
//! - [`vins`]: VINS, publishing the sequence's poses as odometry.

pub mod clock;
pub mod d435i;
pub mod depth;
pub mod vins;

pub use clock::SequenceClock;
