//! Host side (feature `std`): the streaming bytes -> samples decoder, a reader that stamps frames
//! with host monotonic time, and device control over a serial port.

pub mod decoder;
pub mod device;
pub mod reader;

pub use decoder::{Decoder, ImuDecodeReport, ImuSample};
pub use device::{
    compare_rates, ConfigReport, ControlStep, Device, DeviceError, HostBaud, OutputReport, Plan,
    RateDifference, Reply,
};
pub use reader::{Event, Reader};

/// The serial-port crate this module is built on (for opening ports and pseudo-terminals).
pub use serialport;
