//! Synchronisation of the two sensor streams, in two parts: [`clock`] maps each sensor clock to
//! the host clock online; [`order`] uses those maps to release radar frames and IMU samples in
//! time order, declaring a stream missing when it stalls.

pub mod clock;
pub mod order;

pub use clock::{tx_s, ClockConfig, OnlineClock};
pub use order::{FeedOrder, SyncConfig, SyncCounters, SyncOut, Synchroniser};
