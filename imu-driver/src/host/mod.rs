//! Host side (feature `std`): a reader that stamps frames with host monotonic time, and device
//! control over a serial port.

pub mod device;
pub mod reader;
pub mod samples;

pub use device::{
    compare_rates, ConfigReport, ControlStep, Device, DeviceError, HostBaud, OutputReport, Plan,
    RateDifference, Reply,
};
pub use reader::{Event, Reader};
pub use samples::{Samples, TimedSample};

/// The serial-port crate this module is built on (for opening ports and pseudo-terminals).
pub use serialport;
