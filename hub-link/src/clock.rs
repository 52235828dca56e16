//! The receiving side's view of the link's sequence and clock.

use crate::Header;

/// Follows the link's sequence numbers (missing messages, hub restarts) and puts hub time on the
/// receiver's clock by one offset, fixed at the first message: `host = host(first) + (t_hub -
/// t_hub(first))`. It follows the hub's oscillator from there (no drift correction: tens of ppm).
/// A restarted hub (sequence back to 0) re-anchors the offset. Used by the host's `run --hub` and
/// `record --hub`, so both read the link the same way.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkClock {
    /// (hub time, receiver time) of the anchor message \[ns\].
    anchor: Option<(u64, u64)>,
    next_seq: Option<u32>,
    /// Messages missing by sequence number (dropped by the hub for backpressure, or destroyed on
    /// the way).
    pub seq_gaps: u64,
    /// Times the hub restarted.
    pub restarts: u64,
}

/// What [`LinkClock::observe`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Observed {
    /// The message's time on the receiver's clock \[ns\] (0 at the least).
    pub t_ns: u64,
    /// Messages missing just before this one.
    pub missing: u32,
    /// The hub restarted before this message (the clock was re-anchored on it).
    pub restarted: bool,
}

impl LinkClock {
    /// Takes the header of each decoded message, in link order, with the receiver's time of the
    /// read that completed it \[ns\].
    pub fn observe(&mut self, h: &Header, read_ns: u64) -> Observed {
        let mut missing = 0;
        let mut restarted = false;
        if let Some(want) = self.next_seq {
            if h.seq == 0 && want != 0 {
                restarted = true;
                self.restarts += 1;
                self.anchor = None;
            } else if h.seq != want {
                missing = h.seq.wrapping_sub(want);
                self.seq_gaps += u64::from(missing);
            }
        }
        self.next_seq = Some(h.seq.wrapping_add(1));
        let (t0, r0) = *self.anchor.get_or_insert((h.t_ns, read_ns));
        let t = i128::from(r0) + i128::from(h.t_ns) - i128::from(t0);
        Observed {
            t_ns: u64::try_from(t.max(0)).unwrap_or(u64::MAX),
            missing,
            restarted,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn h(seq: u32, t_ns: u64) -> Header {
        Header {
            seq,
            t_ns,
            ..Header::default()
        }
    }

    #[test]
    fn hub_time_on_the_receiver_clock_with_gaps_and_a_restart() {
        let mut c = LinkClock::default();
        // Read times jitter; the mapped times follow the hub.
        assert_eq!(c.observe(&h(5, 9_000), 100).t_ns, 100);
        assert_eq!(c.observe(&h(6, 9_050), 170).t_ns, 150);
        let o = c.observe(&h(9, 9_100), 171);
        assert_eq!((o.t_ns, o.missing, o.restarted), (200, 2, false));
        // Restart: sequence 0, hub time back near boot; re-anchored at its read time.
        let o = c.observe(&h(0, 10), 500);
        assert_eq!((o.t_ns, o.missing, o.restarted), (500, 0, true));
        assert_eq!(c.observe(&h(1, 60), 530).t_ns, 550);
        // Sequence wrap is not a gap.
        let mut w = LinkClock::default();
        w.observe(&h(u32::MAX, 0), 0);
        assert_eq!(w.observe(&h(0, 1), 1).missing, 0);
        assert_eq!((c.seq_gaps, c.restarts, w.restarts), (2, 1, 0));
        // A hub time before the anchor cannot go below zero.
        let mut z = LinkClock::default();
        z.observe(&h(0, 1_000), 10);
        assert_eq!(z.observe(&h(1, 0), 20).t_ns, 0);
    }
}
