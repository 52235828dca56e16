//! Host side: the streaming bytes -> samples decoder (feature `alloc`), a reader that stamps
//! frames with host monotonic time (`std`), and device control over a serial port (`serial`).

pub mod decoder;
#[cfg(feature = "serial")]
pub mod device;
#[cfg(feature = "std")]
pub mod reader;

pub use decoder::{Decoder, ImuDecodeReport, ImuSample, PressureSample};
#[cfg(feature = "serial")]
pub use device::{
    compare_rates, ConfigReport, ControlStep, Device, DeviceError, HostBaud, OutputReport, Plan,
    RateDifference, Reply,
};
#[cfg(feature = "std")]
pub use reader::{Event, Reader};

/// The serial-port crate this module is built on (for opening ports and pseudo-terminals).
#[cfg(feature = "serial")]
pub use serialport;
