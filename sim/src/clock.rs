//! Sensor clocks and serial links: when bytes leave a sensor and when the host reads them.
//!
//! Each sensor counts time on its own oscillator: `sensor = (1 + drift) host + offset` (the
//! session's [`ClockTruth`](milliego_session::ClockTruth) convention). A UART sends one byte per
//! 10 bit times (8N1) at its baud rate; the host's read returns a chunk some time after the
//! chunk's last byte arrived (USB-serial latency).

use crate::rng::SimRng;

/// A sensor's clock relative to the host clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorClock {
    /// Sensor time at host time 0 \[s\].
    pub offset_s: f64,
    /// Rate error \[ppm\]: positive runs fast.
    pub drift_ppm: f64,
}

impl SensorClock {
    /// Sensor time at host time `host_s` \[s\].
    pub fn to_sensor(&self, host_s: f64) -> f64 {
        (1.0 + self.drift_ppm * 1e-6) * host_s + self.offset_s
    }

    /// Host time at sensor time `sensor_s` \[s\].
    pub fn to_host(&self, sensor_s: f64) -> f64 {
        (sensor_s - self.offset_s) / (1.0 + self.drift_ppm * 1e-6)
    }

    /// A random clock: offset in \[lo, hi\] s, drift within ±`ppm`.
    pub fn random(rng: &mut SimRng, lo: f64, hi: f64, ppm: f64) -> SensorClock {
        SensorClock {
            offset_s: rng.uniform(lo, hi),
            drift_ppm: rng.uniform(-ppm, ppm),
        }
    }
}

/// A UART from a sensor to the host, and the host's reads of it.
#[derive(Debug, Clone)]
pub struct Uart {
    /// Baud rate \[bit/s\].
    pub baud: u32,
    /// Host time the line is free again \[s\].
    busy_until: f64,
    /// Host time of the last read returned \[s\] (reads never go back in time).
    last_read: f64,
    /// Smallest and largest read chunk \[B\].
    chunk: (usize, usize),
    /// Host read latency after a chunk's last byte: smallest and largest \[s\].
    latency: (f64, f64),
}

/// One host read: when it returned and how many bytes it carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Read {
    /// Host time the read returned \[ns since session start\].
    pub host_ns: u64,
    /// Bytes in the chunk.
    pub len: usize,
}

impl Uart {
    /// A link at `baud` whose host reads return `chunk.0..=chunk.1` bytes each, `latency`
    /// seconds after their last byte arrived.
    pub fn new(baud: u32, chunk: (usize, usize), latency: (f64, f64)) -> Uart {
        Uart {
            baud,
            busy_until: 0.0,
            last_read: 0.0,
            chunk,
            latency,
        }
    }

    /// Time one byte takes on the line \[s\] (start + 8 data + stop bits).
    pub fn byte_time(&self) -> f64 {
        10.0 / f64::from(self.baud)
    }

    /// Sends `len` bytes that are ready at host time `ready` \[s\] (they wait while the line is
    /// busy). Returns the host time the first byte started \[s\] and the reads that deliver them.
    pub fn send(&mut self, ready: f64, len: usize, rng: &mut SimRng) -> (f64, Vec<Read>) {
        let start = ready.max(self.busy_until);
        let bt = self.byte_time();
        self.busy_until = start + len as f64 * bt;
        let mut reads = Vec::new();
        let mut sent = 0;
        while sent < len {
            let n = (self.chunk.0 + rng.below(self.chunk.1 - self.chunk.0 + 1)).min(len - sent);
            sent += n;
            let arrived = start + sent as f64 * bt;
            let t = (arrived + rng.uniform(self.latency.0, self.latency.1)).max(self.last_read);
            self.last_read = t;
            reads.push(Read {
                host_ns: (t * 1e9).round() as u64,
                len: n,
            });
        }
        (start, reads)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_round_trips_and_uart_paces_bytes() {
        let c = SensorClock {
            offset_s: 12.5,
            drift_ppm: 20.0,
        };
        assert!((c.to_host(c.to_sensor(3.0)) - 3.0).abs() < 1e-12);
        assert!((c.to_sensor(1000.0) - 1000.0 - 12.5 - 0.02).abs() < 1e-9);
        let mut rng = SimRng::new(1, "t");
        let mut u = Uart::new(921_600, (64, 256), (1e-4, 1e-3));
        let (s0, r0) = u.send(0.0, 9216, &mut rng);
        assert_eq!(s0, 0.0);
        assert_eq!(r0.iter().map(|r| r.len).sum::<usize>(), 9216);
        // 9216 B at 921600 baud take 100 ms; a frame ready at 50 ms waits for the line.
        let (s1, _) = u.send(0.05, 10, &mut rng);
        assert!((s1 - 0.1).abs() < 1e-12);
        assert!(r0.last().unwrap().host_ns >= 100_000_000);
    }
}
