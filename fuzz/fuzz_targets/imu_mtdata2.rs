//! Placeholder until the IMU driver lands (replaced on the imu branch).
#![no_main]
use libfuzzer_sys::fuzz_target;
fuzz_target!(|_data: &[u8]| {});
