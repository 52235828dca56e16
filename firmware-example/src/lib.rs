//! What firmware does with the driver cores: feed bytes as the UART DMA delivers them through the
//! radar and IMU framers, decode, and emit poses on the link, all with fixed buffers and no
//! allocator. CI builds this crate for `thumbv7em-none-eabihf` and `thumbv6m-none-eabi`.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

use imu_driver::{DeviceFramer, Message, Value};
use pose_link::{encode_serial, Deframer, Event, PoseMessage, SERIAL_FRAME_MAX};
use radar_driver::tlv::{Dialect, Tlv};
use radar_driver::{Framer, Poll};

/// One SDK 3.3 xWR68xx frame (number 7) with one point {1.0, 2.0, 0.5, -1.5} m, m/s and its side
/// info, padded to 96 B.
#[rustfmt::skip]
pub static RADAR_FRAME: [u8; 96] = [
    0x02, 0x01, 0x04, 0x03, 0x06, 0x05, 0x08, 0x07, 0x02, 0x00, 0x03, 0x03, 0x60, 0x00, 0x00, 0x00,
    0x43, 0x68, 0x0A, 0x00, 0x07, 0x00, 0x00, 0x00, 0x78, 0x56, 0x34, 0x12, 0x01, 0x00, 0x00, 0x00,
    0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x10, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0x3F, 0x00, 0x00, 0xC0, 0xBF,
    0x07, 0x00, 0x00, 0x00, 0x04, 0x00, 0x00, 0x00, 0x7B, 0x00, 0x2D, 0x00, 0x0F, 0x0F, 0x0F, 0x0F,
    0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F,
];

/// One MTData2 message: PacketCounter 258.
pub static IMU_FRAME: [u8; 10] = [0xFA, 0xFF, 0x36, 0x05, 0x10, 0x20, 0x02, 0x01, 0x02, 0x91];

/// What [`run`] saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Report {
    /// Radar frames decoded.
    pub radar_frames: u32,
    /// Radar points decoded.
    pub radar_points: u32,
    /// IMU messages decoded.
    pub imu_messages: u32,
    /// Last PacketCounter seen.
    pub imu_counter: u16,
    /// Pose messages that went through the serial encoder and deframer intact.
    pub poses: u32,
}

/// Feeds `radar` and `imu` in `dma_chunk`-byte pieces (as a UART DMA half-buffer interrupt
/// would), then sends a pose through the serial codec and back.
pub fn run(radar: &[u8], imu: &[u8], dma_chunk: usize) -> Report {
    let mut r = Report::default();
    let mut radar_framer: Framer<512> = Framer::default();
    for chunk in radar.chunks(dma_chunk.max(1)) {
        let mut input = chunk;
        loop {
            match radar_framer.poll(&mut input) {
                Poll::Frame(f) => {
                    r.radar_frames += 1;
                    for t in f.tlvs() {
                        if let Ok(Tlv::Points(p)) = t.decode(Dialect::of(&f)) {
                            r.radar_points += p.len() as u32;
                        }
                    }
                }
                Poll::Dropped { .. } => {}
                Poll::NeedMore => break,
            }
        }
    }
    let mut imu_framer = DeviceFramer::new();
    for chunk in imu.chunks(dma_chunk.max(1)) {
        let mut input = chunk;
        loop {
            match imu_framer.poll(&mut input) {
                imu_driver::Poll::Frame(f) => {
                    r.imu_messages += 1;
                    if let Ok(Message::MtData2(d)) = Message::decode(&f) {
                        for item in d.items().flatten() {
                            if let Ok(Value::PacketCounter(c)) = item.value() {
                                r.imu_counter = c;
                            }
                        }
                    }
                }
                imu_driver::Poll::Dropped { .. } => {}
                imu_driver::Poll::NeedMore => break,
            }
        }
    }
    let pose = PoseMessage {
        seq: r.radar_frames,
        position: [0.1, 0.2, 0.3],
        ..PoseMessage::default()
    };
    let mut wire = [0u8; SERIAL_FRAME_MAX];
    if let Ok(n) = encode_serial(&pose, &mut wire) {
        let mut d: Deframer<SERIAL_FRAME_MAX> = Deframer::default();
        let mut input = &wire[..n];
        if let Event::Message(m) = d.poll(&mut input) {
            r.poses += u32::from(m == pose);
        }
    }
    r
}

#[cfg(test)]
mod tests {
    #[test]
    fn static_buffers_decode_in_any_dma_chunk_size() {
        for chunk in [1, 3, 16, 64, 1000] {
            let r = super::run(&super::RADAR_FRAME, &super::IMU_FRAME, chunk);
            assert_eq!(
                r,
                super::Report {
                    radar_frames: 1,
                    radar_points: 1,
                    imu_messages: 1,
                    imu_counter: 258,
                    poses: 1
                }
            );
        }
    }
}
