//! The milliEgo sensor hub (spec of what it sends: `docs/hub-link.md`; how to build, boot and
//! test it: README "Firmware").
//!
//! * UART1 (radar data port) and UART2 (IMU) receive under interrupts into single-producer rings;
//!   each interrupt also records (bytes received so far, timer time) in a stamp ring.
//! * The main loop frames both streams with the drivers' `no_std` framers, gives each frame the
//!   stamp of the interrupt that received its last byte, and encodes it verbatim, with its hub
//!   time, into the link's transmit ring (COBS streaming encoder: no frame-sized buffer).
//! * UART0 carries the hub link; a health message (every counter, ring high-water marks, the
//!   clock) goes out every second.
//! * Nothing blocks on a full buffer: a full receive ring drops the byte (counted), a full stamp
//!   ring merges stamps (counted), a full transmit ring drops the message (counted, and its
//!   link sequence number is skipped so the host sees the gap).
//!
//! Clock: the core's SysTick at the 50 MHz system clock (PLL from the 8 MHz crystal, as the
//! LM3S6965 evaluation board runs it), extended to 64 bits by its wrap interrupt.
#![no_std]
#![no_main]

mod hw;
mod ring;

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m_rt::{entry, exception};
use hub_link::{encode_serial, serial_len_max, Header, Health, Kind, PortHealth};
use ring::{Ring, StampRing};

/// Hub timer frequency \[Hz\] (SysTick on the 50 MHz core clock).
pub const TIMER_HZ: u32 = 50_000_000;
const NS_PER_TICK: u64 = 1_000_000_000 / TIMER_HZ as u64;
const _: () = assert!(1_000_000_000 % TIMER_HZ == 0);

/// Largest radar frame forwarded \[B\] (larger candidates are rejected by the framer as too
/// long and counted).
pub const RADAR_MAX: usize = 4096;
/// Radar receive ring \[B\]: 44 ms of a 921600 bit/s UART.
pub const RADAR_RING: usize = 8192;
/// IMU receive ring \[B\]: 22 ms at 921600 bit/s (89 ms at an MTi's factory 115200).
pub const IMU_RING: usize = 2048;
/// Link transmit ring \[B\]: two largest radar frames, encoded.
pub const TX_RING: usize = 8192;
/// Interrupt stamps kept per UART (QEMU raises one interrupt per byte: a 1 KiB radar frame
/// takes 1024 of them, of which only the newest matter once the frame is complete).
pub const STAMPS: usize = 256;
/// Health period \[timer ticks\] (1 s).
const HEALTH_PERIOD: u64 = TIMER_HZ as u64;

static RADAR_RX: Ring<RADAR_RING> = Ring::new();
static IMU_RX: Ring<IMU_RING> = Ring::new();
static TX: Ring<TX_RING> = Ring::new();
static RADAR_STAMPS: StampRing<STAMPS> = StampRing::new();
static IMU_STAMPS: StampRing<STAMPS> = StampRing::new();

/// Counters kept by the receive interrupts.
struct IsrCounters {
    rx_bytes: AtomicU32,
    overflow: AtomicU32,
    uart_errors: AtomicU32,
}

impl IsrCounters {
    const fn new() -> Self {
        IsrCounters {
            rx_bytes: AtomicU32::new(0),
            overflow: AtomicU32::new(0),
            uart_errors: AtomicU32::new(0),
        }
    }
}

static RADAR_ISR: IsrCounters = IsrCounters::new();
static IMU_ISR: IsrCounters = IsrCounters::new();
/// Worst receive-interrupt time per byte \[SysTick ticks = core cycles\].
static ISR_MAX_PER_BYTE: AtomicU32 = AtomicU32::new(0);

/// The receive interrupt body shared by both sensor UARTs: drain the FIFO into the ring, then
/// stamp the batch. Runs at the same priority as SysTick, so the clock read is consistent.
fn rx_isr<const N: usize>(
    uart: hw::Uart,
    rx: &Ring<N>,
    stamps: &StampRing<STAMPS>,
    c: &IsrCounters,
) {
    let t_in = hw::systick_val();
    let mut n = 0u32;
    while let Some(d) = uart.read_data() {
        if d & hw::DR_ERRORS != 0 {
            c.uart_errors.fetch_add(1, Ordering::Relaxed);
        }
        if !rx.push(d as u8) {
            c.overflow.fetch_add(1, Ordering::Relaxed);
        }
        n += 1;
    }
    uart.clear_interrupts();
    if n > 0 {
        c.rx_bytes.fetch_add(n, Ordering::Relaxed);
        stamps.push(rx.written(), hw::now_ticks_isr());
        let dt = t_in.wrapping_sub(hw::systick_val()) & 0x00FF_FFFF;
        let per = dt / n;
        if per > ISR_MAX_PER_BYTE.load(Ordering::Relaxed) {
            ISR_MAX_PER_BYTE.store(per, Ordering::Relaxed);
        }
    }
}

/// UART1: radar data port.
extern "C" fn uart1_isr() {
    rx_isr(hw::UART1, &RADAR_RX, &RADAR_STAMPS, &RADAR_ISR);
}

/// UART2: IMU.
extern "C" fn uart2_isr() {
    rx_isr(hw::UART2, &IMU_RX, &IMU_STAMPS, &IMU_ISR);
}

extern "C" fn unused_isr() {}

#[exception]
fn SysTick() {
    hw::systick_wrapped();
}

/// One interrupt vector.
#[repr(C)]
pub union Vector {
    handler: extern "C" fn(),
    reserved: usize,
}

/// The LM3S6965's 48 interrupt vectors (UART0 5, UART1 6, UART2 33).
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
pub static __INTERRUPTS: [Vector; 48] = {
    let mut v = [const {
        Vector {
            handler: unused_isr,
        }
    }; 48];
    v[6] = Vector { handler: uart1_isr };
    v[33] = Vector { handler: uart2_isr };
    v
};

/// The link: sequence numbers, the transmit ring, its counters.
struct Link {
    seq: u32,
    sent: u32,
    dropped: u32,
    dropped_bytes: u32,
}

impl Link {
    /// Encodes one message into the transmit ring, or drops it (counted) when the ring cannot
    /// take the largest encoding of it. The sequence number advances either way.
    fn send(&mut self, kind: Kind, t_ticks: u64, body: &[&[u8]]) {
        let len: usize = body.iter().map(|b| b.len()).sum();
        let need = serial_len_max(len);
        let header = Header {
            flags: 0,
            seq: self.seq,
            t_ns: t_ticks * NS_PER_TICK,
        };
        self.seq = self.seq.wrapping_add(1);
        if TX.free() < need {
            self.dropped = self.dropped.wrapping_add(1);
            self.dropped_bytes = self.dropped_bytes.wrapping_add(need as u32);
            return;
        }
        encode_serial(kind, &header, body, &mut |b| {
            let _ = TX.push(b);
        });
        self.sent = self.sent.wrapping_add(1);
    }
}

/// Moves link bytes into UART0's FIFO while it has room; true when anything is still queued.
fn drain_tx() -> bool {
    loop {
        let chunk = TX.readable();
        if chunk.is_empty() {
            return false;
        }
        let mut n = 0;
        for &b in chunk {
            if !hw::UART0.try_write(b) {
                break;
            }
            n += 1;
        }
        TX.consume(n);
        if n < chunk.len() {
            return true;
        }
    }
}

/// Main-loop state of one sensor port.
#[derive(Default)]
struct PortState {
    forwarded: u32,
    retracted: u32,
}

/// A frame copied out of its framer (the framer's borrow must end before its counters can say
/// where the frame ended), held while a radar frame may still be retracted.
struct Held<const N: usize> {
    buf: [u8; N],
    len: usize,
    t: u64,
    pending: bool,
}

impl<const N: usize> Held<N> {
    const fn new() -> Self {
        Held {
            buf: [0; N],
            len: 0,
            t: 0,
            pending: false,
        }
    }

    fn take(&mut self, b: &[u8]) {
        let n = b.len().min(N);
        self.buf[..n].copy_from_slice(&b[..n]);
        self.len = n;
        self.pending = true;
        // Not stamped yet: the caller stamps it once the framer's borrow has ended.
        self.t = u64::MAX;
    }

    fn send(&mut self, kind: Kind, st: &mut PortState, link: &mut Link) {
        if self.pending {
            link.send(kind, self.t, &[&self.buf[..self.len]]);
            st.forwarded = st.forwarded.wrapping_add(1);
            self.pending = false;
        }
    }
}

/// The stamp of the interrupt that received byte `end - 1` of a stream (bytes counted as the
/// ring received them).
fn stamp_of(stamps: &StampRing<STAMPS>, end: u64) -> u64 {
    stamps.find(end as u32).unwrap_or_else(hw::now_ticks)
}

/// Frames what the radar ring holds; true when there was anything.
fn service_radar(
    framer: &mut radar_driver::Framer<RADAR_MAX>,
    held: &mut Held<RADAR_MAX>,
    st: &mut PortState,
    link: &mut Link,
) -> bool {
    let chunk = RADAR_RX.readable();
    if chunk.is_empty() {
        return false;
    }
    let mut input = chunk;
    loop {
        let mut retract = false;
        let mut need_more = false;
        match framer.poll(&mut input) {
            radar_driver::Poll::Frame(f) => {
                // A frame framed after the held one settles it.
                held.send(Kind::Radar, st, link);
                held.take(f.as_bytes());
            }
            radar_driver::Poll::Dropped { error, .. } => {
                retract = matches!(error, radar_driver::FrameError::OverlapsNextFrame { .. });
            }
            radar_driver::Poll::NeedMore => need_more = true,
        }
        if held.pending && held.t == u64::MAX {
            // Just taken: the frame ends where the framer's consumed bytes, less what it holds
            // back, end.
            let c = framer.counters().bytes_in - framer.buffered() as u64;
            held.t = stamp_of(&RADAR_STAMPS, c);
        }
        if retract && held.pending {
            held.pending = false;
            st.retracted = st.retracted.wrapping_add(1);
        }
        if held.pending && !framer.may_retract() {
            held.send(Kind::Radar, st, link);
        }
        if need_more {
            break;
        }
    }
    RADAR_RX.consume(chunk.len());
    RADAR_STAMPS.prune((framer.counters().bytes_in - framer.buffered() as u64) as u32);
    true
}

/// Frames what the IMU ring holds; true when there was anything.
fn service_imu(
    framer: &mut imu_driver::DeviceFramer,
    held: &mut Held<IMU_MAX>,
    st: &mut PortState,
    link: &mut Link,
) -> bool {
    let chunk = IMU_RX.readable();
    if chunk.is_empty() {
        return false;
    }
    let mut input = chunk;
    loop {
        match framer.poll(&mut input) {
            imu_driver::Poll::Frame(f) => held.take(f.as_bytes()),
            imu_driver::Poll::Dropped { .. } => continue,
            imu_driver::Poll::NeedMore => break,
        }
        let c = framer.counters().bytes_in - framer.buffered() as u64;
        held.t = stamp_of(&IMU_STAMPS, c);
        held.send(Kind::Imu, st, link);
    }
    IMU_RX.consume(chunk.len());
    IMU_STAMPS.prune((framer.counters().bytes_in - framer.buffered() as u64) as u32);
    true
}

/// Largest Xbus message forwarded \[B\] (the framer's capacity: 2048-byte payloads).
const IMU_MAX: usize = imu_driver::frame_capacity(2048);

fn port_health(
    isr: &IsrCounters,
    ring_hw: u32,
    c_ok: u64,
    c_bad: u64,
    skipped: u64,
    resyncs: u64,
    st: &PortState,
) -> PortHealth {
    PortHealth {
        rx_bytes: isr.rx_bytes.load(Ordering::Relaxed),
        ring_overflow: isr.overflow.load(Ordering::Relaxed),
        ring_high_water: ring_hw,
        uart_errors: isr.uart_errors.load(Ordering::Relaxed),
        frames_ok: c_ok as u32,
        frames_bad: c_bad as u32,
        bytes_skipped: skipped as u32,
        resyncs: resyncs as u32,
        frames_forwarded: st.forwarded,
        frames_retracted: st.retracted,
    }
}

#[entry]
fn main() -> ! {
    // The big state lives in statics (counted in the static RAM figure), handed out once.
    let (radar_framer, imu_framer, radar_held, imu_held) = cortex_m::singleton!(: (
        radar_driver::Framer<RADAR_MAX>,
        imu_driver::DeviceFramer,
        Held<RADAR_MAX>,
        Held<IMU_MAX>,
    ) = (
        radar_driver::Framer::new(radar_driver::LayoutHint::Auto),
        imu_driver::Framer::new(),
        Held::new(),
        Held::new(),
    ))
    .map(|(a, b, c, d)| (a, b, c, d))
    .unwrap_or_else(|| hw::reset());

    hw::init_clock();
    hw::init_systick();
    hw::UART0.init(hw::BAUD_LINK, false);
    hw::UART1.init(hw::BAUD_RADAR, true);
    hw::UART2.init(hw::BAUD_IMU, true);
    hw::enable_irqs();

    let mut link = Link {
        seq: 0,
        sent: 0,
        dropped: 0,
        dropped_bytes: 0,
    };
    let (mut radar, mut imu) = (PortState::default(), PortState::default());
    let mut next_health = hw::now_ticks() + HEALTH_PERIOD;
    loop {
        let mut busy = false;
        busy |= service_radar(radar_framer, radar_held, &mut radar, &mut link);
        busy |= service_imu(imu_framer, imu_held, &mut imu, &mut link);
        let now = hw::now_ticks();
        if now >= next_health {
            next_health = now + HEALTH_PERIOD;
            let rc = radar_framer.counters();
            let ic = imu_framer.counters();
            let h = Health {
                timer_hz: TIMER_HZ,
                radar: port_health(
                    &RADAR_ISR,
                    RADAR_RX.high_water(),
                    rc.frames_ok,
                    rc.frames_bad_total(),
                    rc.bytes_skipped,
                    rc.resyncs,
                    &radar,
                ),
                imu: port_health(
                    &IMU_ISR,
                    IMU_RX.high_water(),
                    ic.frames_ok,
                    ic.frames_bad_total(),
                    ic.bytes_skipped,
                    ic.resyncs,
                    &imu,
                ),
                link_sent: link.sent,
                link_dropped: link.dropped,
                link_dropped_bytes: link.dropped_bytes,
                link_high_water: TX.high_water(),
                stamps_merged: RADAR_STAMPS.merged() + IMU_STAMPS.merged(),
                isr_max_per_byte: ISR_MAX_PER_BYTE.load(Ordering::Relaxed),
                isr_clock: 2,
                capacities: [RADAR_RING as u32, IMU_RING as u32, TX_RING as u32],
            };
            link.send(Kind::Health, now, &[&h.to_bytes()]);
        }
        busy |= drain_tx();
        if !busy {
            hw::sleep_unless_pending(|| {
                !RADAR_RX.readable().is_empty() || !IMU_RX.readable().is_empty()
            });
        }
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    // Never hang: start over (the host sees the link sequence restart at 0).
    hw::reset()
}
