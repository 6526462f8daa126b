//! `topspin check tracker`: what a lab's tracker sends, seen from the
//! tracker port without the rest of the daemon. [`TrackerCheck`] is the
//! sans-IO accumulator (datagrams and their arrival times in, a
//! [`TrackerReport`] out: sources, rate, sequence gaps, duplicates and
//! reordering, capture-to-arrival jitter and the clock mapping, whether the
//! positions look like the table frame, bad datagrams by kind); [`listen`]
//! is its thin socket shell.

use std::collections::BTreeMap;
use std::io;
use std::net::{SocketAddr, UdpSocket};

use serde::Serialize;
use topspin_core::stats::quantile_sorted;
use topspin_core::time::Instant;
use topspin_core::wire::{Observation, WireError};

/// A resting ball's centre height, m (its radius).
const BALL_RADIUS: f64 = 0.02;
/// How close to the ball's radius a ball at rest must read, m.
const REST_TOLERANCE: f64 = 0.005;

/// The accumulator (see the module doc).
#[derive(Debug, Default)]
pub struct TrackerCheck {
    sources: BTreeMap<SocketAddr, u64>,
    bad: BTreeMap<&'static str, u64>,
    accepted: u64,
    first: Option<Instant>,
    last: Option<Instant>,
    last_seq: Option<u32>,
    gaps: u64,
    missing: u64,
    duplicates: u64,
    reordered: u64,
    /// (arrival, arrival − capture) in ns, per accepted datagram.
    delays: Vec<(u64, i128)>,
    heights: Vec<f64>,
    below_table: u64,
}

/// What [`TrackerCheck`] saw.
#[derive(Clone, Debug, Serialize)]
pub struct TrackerReport {
    /// Datagrams per sender address.
    pub sources: BTreeMap<String, u64>,
    /// Valid TTB1 observations.
    pub accepted: u64,
    /// Rejected datagrams by reason (`wrong_length`, `wrong_magic`,
    /// `non_finite`, `out_of_box`, `bad_residual`, `reserved_flags`).
    pub bad: BTreeMap<String, u64>,
    /// Accepted observations per second between the first and the last.
    pub rate_hz: Option<f64>,
    /// Jumps in the sequence number, and the numbers skipped in them.
    pub seq_gaps: u64,
    /// Sequence numbers skipped in those jumps.
    pub seq_missing: u64,
    /// The same sequence number again.
    pub duplicates: u64,
    /// A sequence number behind the last (reordering or a restart).
    pub reordered: u64,
    /// Clock mapping: the minimum of (arrival − capture), ns; the tracker's
    /// clock plus this offset is ours (before the configured fixed latency).
    pub clock_offset_ns: Option<i128>,
    /// The tracker's clock against ours over the run, ppm (from the
    /// minimum offsets of the run's first and last quarter).
    pub clock_drift_ppm: Option<f64>,
    /// Capture-to-arrival jitter above that minimum, µs: p50 / p99 / max.
    pub jitter_us: Option<[f64; 3]>,
    /// Median ball height, m.
    pub z_median_m: Option<f64>,
    /// Share of observations within 5 mm of the ball's radius (a ball at rest
    /// on the table reads z ≈ 0.02 m in the table frame).
    pub at_rest_share: f64,
    /// Observations below the table surface by more than 5 mm.
    pub below_table: u64,
    /// Findings in words, one per line (empty when nothing is amiss).
    pub findings: Vec<String>,
}

fn kind(e: &WireError) -> &'static str {
    match e {
        WireError::WrongLength { .. } => "wrong_length",
        WireError::WrongMagic { .. } => "wrong_magic",
        WireError::NonFinite => "non_finite",
        WireError::OutOfBox { .. } => "out_of_box",
        WireError::BadResidual { .. } => "bad_residual",
        WireError::ReservedFlags { .. } => "reserved_flags",
    }
}

impl TrackerCheck {
    /// An empty check.
    pub fn new() -> Self {
        Self::default()
    }

    /// One datagram from `from`, received at `arrival` on our clock.
    pub fn datagram(&mut self, bytes: &[u8], from: SocketAddr, arrival: Instant) {
        *self.sources.entry(from).or_default() += 1;
        let o = match Observation::parse(bytes) {
            Ok(o) => o,
            Err(e) => {
                *self.bad.entry(kind(&e)).or_default() += 1;
                return;
            }
        };
        self.accepted += 1;
        self.first.get_or_insert(arrival);
        self.last = Some(arrival);
        if let Some(last) = self.last_seq {
            let step = o.seq.wrapping_sub(last);
            if step == 0 {
                self.duplicates += 1;
            } else if step > u32::MAX / 2 {
                self.reordered += 1;
            } else if step > 1 {
                self.gaps += 1;
                self.missing += u64::from(step - 1);
            }
        }
        if self.last_seq.is_none_or(|l| o.seq.wrapping_sub(l) < u32::MAX / 2) {
            self.last_seq = Some(o.seq);
        }
        self.delays.push((arrival.as_nanos(), i128::from(arrival.as_nanos()) - i128::from(o.capture.as_nanos())));
        let z = f64::from(o.pos[2]);
        self.heights.push(z);
        if z < -REST_TOLERANCE {
            self.below_table += 1;
        }
    }

    /// The report so far.
    pub fn report(&self) -> TrackerReport {
        let rate_hz = match (self.first, self.last) {
            (Some(a), Some(b)) if b > a && self.accepted > 1 => {
                Some((self.accepted - 1) as f64 / (b - a).as_secs_f64())
            }
            _ => None,
        };
        let offset = self.delays.iter().map(|d| d.1).min();
        let jitter_us = offset.map(|m| {
            let mut j: Vec<f64> = self.delays.iter().map(|d| (d.1 - m) as f64 * 1e-3).collect();
            j.sort_by(f64::total_cmp);
            [quantile_sorted(&j, 0.5), quantile_sorted(&j, 0.99), j[j.len() - 1]]
        });
        let clock_drift_ppm = (self.delays.len() >= 8).then(|| {
            let q = self.delays.len() / 4;
            let (head, tail) = (&self.delays[..q], &self.delays[self.delays.len() - q..]);
            let min = |s: &[(u64, i128)]| s.iter().min_by_key(|d| d.1).copied().expect("non-empty");
            let (a, b) = (min(head), min(tail));
            let span = b.0.saturating_sub(a.0) as f64;
            if span > 0.0 { (b.1 - a.1) as f64 / span * 1e6 } else { 0.0 }
        });
        let mut z = self.heights.clone();
        z.sort_by(f64::total_cmp);
        let z_median_m = (!z.is_empty()).then(|| quantile_sorted(&z, 0.5));
        let at_rest = z.iter().filter(|h| (**h - BALL_RADIUS).abs() <= REST_TOLERANCE).count();
        let at_rest_share = if z.is_empty() { 0.0 } else { at_rest as f64 / z.len() as f64 };
        let mut findings = Vec::new();
        if self.accepted == 0 {
            findings.push("no valid TTB1 observation arrived: check the tracker's target address and port".into());
        }
        if self.sources.len() > 1 {
            findings.push(format!(
                "{} senders: configure network.tracker_source to the tracker's address",
                self.sources.len()
            ));
        }
        if !self.bad.is_empty() {
            findings.push("bad datagrams arrived (see `bad`): they are dropped and counted by the daemon".into());
        }
        if self.below_table > 0 {
            findings.push(format!(
                "{} observations more than 5 mm below the table surface: is z up, and the origin on the table's surface?",
                self.below_table
            ));
        }
        if let Some(d) = clock_drift_ppm
            && d.abs() > 200.0
        {
            findings.push(format!("the tracker's clock runs {d:+.0} ppm against ours: is it monotonic and in ns?"));
        }
        TrackerReport {
            sources: self.sources.iter().map(|(a, n)| (a.to_string(), *n)).collect(),
            accepted: self.accepted,
            bad: self.bad.iter().map(|(k, n)| ((*k).to_owned(), *n)).collect(),
            rate_hz,
            seq_gaps: self.gaps,
            seq_missing: self.missing,
            duplicates: self.duplicates,
            reordered: self.reordered,
            clock_offset_ns: offset,
            clock_drift_ppm,
            jitter_us,
            z_median_m,
            at_rest_share,
            below_table: self.below_table,
            findings,
        }
    }
}

/// Listens on `bind` for `seconds` (our clock from `now`) and checks every
/// datagram that arrives.
pub fn listen(bind: SocketAddr, seconds: f64, now: impl Fn() -> Instant) -> io::Result<TrackerReport> {
    let socket = UdpSocket::bind(bind)?;
    socket.set_read_timeout(Some(std::time::Duration::from_millis(50)))?;
    let mut check = TrackerCheck::new();
    let mut buf = [0u8; 2048];
    let start = now();
    while (now() - start).as_secs_f64() < seconds {
        match socket.recv_from(&mut buf) {
            Ok((n, from)) => check.datagram(&buf[..n], from, now()),
            Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
            Err(e) => return Err(e),
        }
    }
    Ok(check.report())
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::wire::OBSERVATION_LEN;

    fn datagram(seq: u32, capture_ns: u64, pos: [f32; 3]) -> [u8; OBSERVATION_LEN] {
        let mut b = [0u8; OBSERVATION_LEN];
        Observation { seq, capture: Instant(capture_ns), pos, residual: f32::NAN, cameras: 2, valid: true }
            .emit(&mut b);
        b
    }

    #[test]
    fn a_tracker_at_200_hz_with_faults_is_described_exactly() {
        let from: SocketAddr = "10.0.0.5:5000".parse().unwrap();
        let mut c = TrackerCheck::new();
        // 200 Hz, the tracker's clock 1 s behind ours, 2 ms latency plus a
        // 0–300 µs jitter; seq 10 lost, 20 sent twice, 30 and 31 swapped.
        let mut seqs: Vec<u32> = (0..100).filter(|s| *s != 10).collect();
        seqs.insert(20, 20);
        let k = seqs.iter().position(|s| *s == 30).unwrap();
        seqs.swap(k, k + 1);
        for (i, &s) in seqs.iter().enumerate() {
            let capture = 5_000_000_000 + u64::from(s) * 5_000_000;
            let arrival = capture + 1_000_000_000 + 2_000_000 + (i as u64 % 4) * 100_000;
            c.datagram(&datagram(s, capture, [0.1, 0.2, 0.02]), from, Instant(arrival));
        }
        c.datagram(b"TTB1 too short", from, Instant(0));
        c.datagram(&[0u8; OBSERVATION_LEN], from, Instant(0));
        let r = c.report();
        assert_eq!(r.accepted, 100);
        assert_eq!((r.seq_gaps, r.seq_missing, r.duplicates), (2, 2, 1), "{r:?}");
        assert_eq!(r.reordered, 1);
        assert_eq!(r.bad.get("wrong_length"), Some(&1));
        assert_eq!(r.bad.get("wrong_magic"), Some(&1));
        assert_eq!(r.clock_offset_ns, Some(1_002_000_000));
        assert_eq!(r.jitter_us.map(|j| j[2]), Some(300.0));
        assert!(r.clock_drift_ppm.unwrap().abs() < 1e-9);
        assert!((r.rate_hz.unwrap() - 200.0).abs() < 5.0, "{:?}", r.rate_hz);
        assert_eq!(r.at_rest_share, 1.0);
        assert_eq!(r.sources.get("10.0.0.5:5000"), Some(&102));
        assert_eq!(r.findings.len(), 1, "{:?}", r.findings);
    }

    #[test]
    fn a_z_down_frame_is_named() {
        let from: SocketAddr = "127.0.0.1:1".parse().unwrap();
        let mut c = TrackerCheck::new();
        for s in 0..10 {
            c.datagram(
                &datagram(s, u64::from(s) * 5_000_000, [0.0, 0.0, -0.3]),
                from,
                Instant(u64::from(s) * 5_000_000),
            );
        }
        let r = c.report();
        assert_eq!(r.below_table, 10);
        assert!(r.findings.iter().any(|f| f.contains("below the table")), "{:?}", r.findings);
    }
}
