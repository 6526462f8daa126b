//! Ingest of ball observations (DESIGN §5.1): one datagram with its source
//! address and arrival time in, a validated observation on our clock out —
//! or a counted reason to drop it. Sans-IO (the ingest thread owns the
//! socket), allocation-free, never panics on any input.
//!
//! Dropped and counted: datagrams from a source other than the configured
//! tracker, malformed ones (length, magic, non-finite or implausible
//! coordinates, reserved flags), ones the tracker marked not valid,
//! duplicates and out-of-order sequence numbers. A sequence number behind
//! the last one with a newer capture time, or far behind it, is a tracker
//! restart, not reordering.

pub(crate) mod clock;

use std::net::{IpAddr, SocketAddr};

use crate::physics::Vec3;
use crate::time::Instant;
use crate::wire::observation::{Observation, WireError};
pub use clock::ClockMap;

/// A sequence number this far behind the last accepted one means the
/// tracker restarted.
pub(crate) const RESTART_GAP: u32 = 10_000;

/// An observation ready for the estimator.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Accepted {
    /// The tracker's sequence number.
    pub seq: u32,
    /// Capture time on our clock.
    pub capture: Instant,
    /// Position in the table frame, m.
    pub pos: Vec3,
}

/// Why a datagram was dropped.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Dropped {
    /// From an address other than the configured tracker.
    Foreign,
    /// Not a usable observation datagram.
    Malformed(WireError),
    /// The tracker flagged it as not a ball.
    NotValid,
    /// The same sequence number again.
    Duplicate,
    /// Older than one already accepted.
    OutOfOrder,
}

/// What the ingest has seen, by outcome.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct IngestCounters {
    /// Datagrams passed on as observations.
    pub accepted: u64,
    /// Dropped: from a source other than the tracker.
    pub foreign: u64,
    /// Dropped: not a usable observation datagram.
    pub malformed: u64,
    /// Dropped: flagged by the tracker as not a ball.
    pub not_valid: u64,
    /// Dropped: the same sequence number again.
    pub duplicate: u64,
    /// Dropped: older than one already accepted.
    pub out_of_order: u64,
    /// Sequence numbers that went back because the tracker restarted (the
    /// datagram is accepted).
    pub tracker_restarts: u64,
    /// Jumps of the tracker's clock seen by the [`ClockMap`].
    pub clock_jumps: u64,
}

/// The ingest state: source filter, sequence tracking, clock mapping.
///
/// One tracker datagram in (its bytes, where from, when it arrived on our
/// clock), one observation on our clock out; everything else is counted:
///
/// ```
/// use std::net::SocketAddr;
/// use topspin_core::ingest::{Dropped, Ingest};
/// use topspin_core::time::Instant;
/// use topspin_core::wire::{OBSERVATION_LEN, Observation};
///
/// let tracker: SocketAddr = "192.168.1.20:5000".parse().unwrap();
/// let mut ingest = Ingest::new(Some(tracker.ip()), 0);
///
/// let obs = Observation {
///     seq: 1,
///     capture: Instant(5_000_000_000),
///     pos: [-1.2, 0.1, 0.3],
///     residual: 0.001,
///     cameras: 4,
///     valid: true,
/// };
/// let mut datagram = [0u8; OBSERVATION_LEN];
/// obs.emit(&mut datagram);
///
/// let got = ingest.accept(&datagram, tracker, Instant(7_000_000)).unwrap();
/// assert_eq!(got.seq, 1);
/// assert!((got.pos.x + 1.2).abs() < 1e-6);
/// // The same datagram again, and one from elsewhere: dropped, counted.
/// assert_eq!(ingest.accept(&datagram, tracker, Instant(7_100_000)), Err(Dropped::Duplicate));
/// let stranger: SocketAddr = "10.0.0.9:5000".parse().unwrap();
/// assert_eq!(ingest.accept(&datagram, stranger, Instant(7_200_000)), Err(Dropped::Foreign));
/// let c = ingest.counters();
/// assert_eq!((c.accepted, c.duplicate, c.foreign), (1, 1, 1));
/// ```
#[derive(Debug, Clone)]
pub struct Ingest {
    allowed_source: Option<IpAddr>,
    last_seq: Option<u32>,
    last_capture_ns: u64,
    clock: ClockMap,
    counters: IngestCounters,
}

impl Ingest {
    /// `allowed_source`: the tracker's address (`None` accepts any; the
    /// daemon's configuration always names one). `fixed_latency_ns`: see
    /// [`ClockMap::new`].
    pub fn new(allowed_source: Option<IpAddr>, fixed_latency_ns: u64) -> Self {
        Ingest {
            allowed_source,
            last_seq: None,
            last_capture_ns: 0,
            clock: ClockMap::new(fixed_latency_ns),
            counters: Default::default(),
        }
    }

    /// The counters so far, clock jumps included.
    pub fn counters(&self) -> IngestCounters {
        IngestCounters { clock_jumps: self.clock.jumps(), ..self.counters }
    }

    /// Takes one datagram.
    pub fn accept(&mut self, bytes: &[u8], from: SocketAddr, arrival: Instant) -> Result<Accepted, Dropped> {
        let outcome = self.classify(bytes, from, arrival);
        let c = &mut self.counters;
        match outcome {
            Ok(_) => c.accepted += 1,
            Err(Dropped::Foreign) => c.foreign += 1,
            Err(Dropped::Malformed(_)) => c.malformed += 1,
            Err(Dropped::NotValid) => c.not_valid += 1,
            Err(Dropped::Duplicate) => c.duplicate += 1,
            Err(Dropped::OutOfOrder) => c.out_of_order += 1,
        }
        outcome
    }

    fn classify(&mut self, bytes: &[u8], from: SocketAddr, arrival: Instant) -> Result<Accepted, Dropped> {
        if self.allowed_source.is_some_and(|ip| ip != from.ip()) {
            return Err(Dropped::Foreign);
        }
        let obs = Observation::parse(bytes).map_err(Dropped::Malformed)?;
        if !obs.valid {
            return Err(Dropped::NotValid);
        }
        if let Some(last) = self.last_seq {
            let ahead = obs.seq.wrapping_sub(last);
            if ahead == 0 {
                return Err(Dropped::Duplicate);
            }
            if ahead > u32::MAX / 2 {
                // Behind the last one: reordering (an older capture), or a
                // restarted tracker (a newer capture, or far behind).
                if last.wrapping_sub(obs.seq) < RESTART_GAP && obs.capture.as_nanos() <= self.last_capture_ns {
                    return Err(Dropped::OutOfOrder);
                }
                self.counters.tracker_restarts += 1;
            }
        }
        self.last_seq = Some(obs.seq);
        self.last_capture_ns = obs.capture.as_nanos();
        let capture = self.clock.map(obs.capture.as_nanos(), arrival);
        let [x, y, z] = obs.pos;
        Ok(Accepted { seq: obs.seq, capture, pos: Vec3::new(x as f64, y as f64, z as f64) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::observation::OBSERVATION_LEN;
    use proptest::prelude::*;

    const TRACKER: &str = "127.0.0.2:9000";

    fn datagram(seq: u32, capture_ns: u64, valid: bool) -> [u8; OBSERVATION_LEN] {
        let mut buf = [0u8; OBSERVATION_LEN];
        Observation {
            seq,
            capture: Instant::from_nanos(capture_ns),
            pos: [0.1, 0.2, 0.3],
            residual: f32::NAN,
            cameras: 2,
            valid,
        }
        .emit(&mut buf);
        buf
    }

    #[test]
    fn every_kind_of_bad_datagram_is_counted() {
        let from: SocketAddr = TRACKER.parse().unwrap();
        let mut ing = Ingest::new(Some(from.ip()), 0);
        let t = Instant::from_nanos(1_000_000_000);
        assert!(ing.accept(&datagram(10, 1000, true), from, t).is_ok());
        assert_eq!(ing.accept(&datagram(10, 1000, true), from, t), Err(Dropped::Duplicate));
        assert_eq!(ing.accept(&datagram(9, 900, true), from, t), Err(Dropped::OutOfOrder));
        assert_eq!(ing.accept(&datagram(11, 1100, false), from, t), Err(Dropped::NotValid));
        assert_eq!(ing.accept(&datagram(12, 1200, true), "10.0.0.9:9000".parse().unwrap(), t), Err(Dropped::Foreign));
        assert!(matches!(ing.accept(&[0u8; 7], from, t), Err(Dropped::Malformed(WireError::WrongLength { len: 7 }))));
        assert!(ing.accept(&datagram(13, 1300, true), from, t).is_ok());
        // A restarted tracker starts counting again.
        assert!(ing.accept(&datagram(0, 2000, true), from, t).is_ok());
        let c = ing.counters();
        assert_eq!(
            (c.accepted, c.duplicate, c.out_of_order, c.not_valid, c.foreign, c.malformed, c.tracker_restarts),
            (3, 1, 1, 1, 1, 1, 1)
        );
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..64), seq in any::<u32>()) {
            let from: SocketAddr = TRACKER.parse().unwrap();
            let mut ing = Ingest::new(None, 0);
            let _ = ing.accept(&datagram(seq, 5, true), from, Instant::from_nanos(10));
            let _ = ing.accept(&bytes, from, Instant::from_nanos(20));
            let c = ing.counters();
            prop_assert_eq!(c.accepted + c.malformed + c.duplicate + c.out_of_order + c.not_valid, 2);
        }
    }
}
