//! A seeded fault injector around the simulated tracker's datagrams
//! (smoltcp's `FaultInjector` pattern: the daemon has no fault `if`s, the
//! stream is mistreated on its way in). The clean stream is planned first
//! (`plan_datagrams`: every TTB1 datagram with its send time), then
//! `inject` loses, silences, duplicates, reorders, teleports and
//! re-clocks it and mixes in garbage and a foreign "ball", and
//! `send_planned` paces the result onto the sockets.

use std::io;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::SimBall;
use super::udp_tracker::{RETURN_SEQ_ROOM, StreamStats, capture_time};
use topspin_core::time::{Duration, Instant};
use topspin_core::wire::{OBSERVATION_LEN, Observation, ObservationPacket};
use topspin_daemon::clock;

/// Longest datagram the injector writes (garbage included).
pub(crate) const MAX_PLANNED_LEN: usize = 64;

/// Which socket a datagram leaves from.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Sender {
    /// The configured tracker's address.
    Tracker,
    /// Another address (a second tracker, a stray device).
    Foreign,
}

/// One datagram and when to send it.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) struct Planned {
    pub at: Instant,
    pub from: Sender,
    pub len: usize,
    pub bytes: [u8; MAX_PLANNED_LEN],
}

impl Planned {
    pub(crate) fn bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

/// What the tracker side does wrong. Probabilities are per observation,
/// rates per second of stream; the default does nothing.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct TrackerFaults {
    /// Observations lost at random.
    pub loss: f64,
    /// Bursts of silence (no datagram at all) per second, each `silence_len` s.
    pub silence_rate: f64,
    /// Length of each silence, s.
    pub silence_len: f64,
    /// Observations sent twice.
    pub duplicate: f64,
    /// Observations sent `reorder_by` s late (after their successors).
    pub reorder: f64,
    /// How late a reordered observation is sent, s.
    pub reorder_by: f64,
    /// Garbage datagrams per second (random bytes, some with the TTB1 magic).
    pub garbage_rate: f64,
    /// A second "ball" (each real ball mirrored across the table, a little
    /// later) from a foreign address.
    pub foreign_ball: bool,
    /// Observations whose position jumps across the table (x, y mirrored).
    pub teleport: f64,
    /// The tracker's clock jumps by `clock_jump_by` s (capture times, not
    /// arrivals) for every datagram sent `clock_jump_at` s after the first.
    pub clock_jump_at: Option<f64>,
    /// The jump added to capture times, s (see `clock_jump_at`).
    pub clock_jump_by: f64,
}

impl Default for TrackerFaults {
    fn default() -> Self {
        TrackerFaults {
            loss: 0.0,
            silence_rate: 0.0,
            silence_len: 0.1,
            duplicate: 0.0,
            reorder: 0.0,
            reorder_by: 0.015,
            garbage_rate: 0.0,
            foreign_ball: false,
            teleport: 0.0,
            clock_jump_at: None,
            clock_jump_by: 0.0,
        }
    }
}

impl TrackerFaults {
    /// Every fault at once: 20 % loss, a 100 ms silence about
    /// every 2 s, 5 % duplicates, 5 % reordered by 15 ms, garbage at 10× a
    /// 150 Hz tracker, a foreign ball, 1 % teleports, a +2 s clock jump 3 s in.
    pub fn all() -> Self {
        TrackerFaults {
            loss: 0.2,
            silence_rate: 0.5,
            silence_len: 0.1,
            duplicate: 0.05,
            reorder: 0.05,
            reorder_by: 0.015,
            garbage_rate: 1500.0,
            foreign_ball: true,
            teleport: 0.01,
            clock_jump_at: Some(3.0),
            clock_jump_by: 2.0,
        }
    }
}

/// What `inject` did.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct InjectedCounts {
    /// Datagrams in the clean plan.
    pub clean: u64,
    /// Observations dropped at random (`loss`).
    pub lost: u64,
    /// Observations dropped inside a silence.
    pub silenced: u64,
    /// Observations sent twice.
    pub duplicated: u64,
    /// Observations sent `reorder_by` late.
    pub reordered: u64,
    /// Garbage datagrams added.
    pub garbage: u64,
    /// Datagrams of the foreign ball added.
    pub foreign: u64,
    /// Observations whose position was mirrored across the table.
    pub teleported: u64,
    /// Observations whose capture time the clock jump shifted.
    pub clock_jumped: u64,
}

pub(crate) fn observation(seq: u32, capture: Instant, pos: [f32; 3]) -> Planned {
    let mut buf = [0u8; OBSERVATION_LEN];
    Observation { seq, capture, pos, residual: f32::NAN, cameras: 2, valid: true }.emit(&mut buf);
    let mut bytes = [0u8; MAX_PLANNED_LEN];
    bytes[..OBSERVATION_LEN].copy_from_slice(&buf);
    Planned { at: capture, from: Sender::Tracker, len: OBSERVATION_LEN, bytes }
}

/// The first sequence number after ball `k`'s observations in
/// [`plan_datagrams`]: its return's.
pub(crate) fn return_seq(balls: &[SimBall], k: usize) -> u32 {
    let before: usize = balls[..k].iter().map(|b| b.observations.len()).sum();
    (before as u32)
        .wrapping_add(RETURN_SEQ_ROOM.wrapping_mul(k as u32))
        .wrapping_add(balls[k].observations.len() as u32)
}

/// The clean stream: every observation of `balls` (ball k launched
/// `starts[k]` s after `t0`) sent at capture + `latency`, in order; each
/// ball's sequence numbers [`RETURN_SEQ_ROOM`] after the last's.
pub(crate) fn plan_datagrams(balls: &[SimBall], starts: &[f64], latency: f64, t0: Instant) -> Vec<Planned> {
    let latency = Duration::from_nanos((latency.max(0.0) * 1e9) as u64);
    let mut seq: u32 = 0;
    let mut out = Vec::with_capacity(balls.iter().map(|b| b.observations.len()).sum());
    for (b, &start) in balls.iter().zip(starts) {
        for o in &b.observations {
            let capture = capture_time(t0, start, o.t);
            let mut p = observation(seq, capture, [o.pos.x as f32, o.pos.y as f32, o.pos.z as f32]);
            p.at = capture + latency;
            out.push(p);
            seq = seq.wrapping_add(1);
        }
        seq = seq.wrapping_add(RETURN_SEQ_ROOM);
    }
    out
}

fn secs(d: f64) -> Duration {
    Duration::from_nanos((d.max(0.0) * 1e9) as u64)
}

/// Applies `faults` to a clean plan (seeded); the result is sorted by send
/// time.
pub(crate) fn inject(clean: &[Planned], faults: &TrackerFaults, seed: u64) -> (Vec<Planned>, InjectedCounts) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7472_6163_6b65_7246);
    let mut n = InjectedCounts { clean: clean.len() as u64, ..Default::default() };
    let (Some(first), Some(last)) = (clean.first(), clean.last()) else {
        return (Vec::new(), n);
    };
    let (start, end) = (first.at, last.at);
    let span = (end - start).0 as f64 * 1e-9;
    // Silences: a Poisson number of bursts at uniform times.
    let mut silences: Vec<(Instant, Instant)> = Vec::new();
    let mut t = 0.0;
    if faults.silence_rate > 0.0 {
        loop {
            t += -rng.random::<f64>().max(1e-12).ln() / faults.silence_rate;
            if t > span {
                break;
            }
            let from = start + secs(t);
            silences.push((from, from + secs(faults.silence_len)));
        }
    }
    let jump_from = faults.clock_jump_at.map(|a| start + secs(a));
    let jump_ns = (faults.clock_jump_by * 1e9) as i64;
    let mut out = Vec::with_capacity(clean.len() * 2);
    for p in clean {
        let mut p = *p;
        if silences.iter().any(|(a, b)| (*a..*b).contains(&p.at)) {
            n.silenced += 1;
            continue;
        }
        if rng.random::<f64>() < faults.loss {
            n.lost += 1;
            continue;
        }
        let Ok(mut pkt) = ObservationPacket::new_checked(&mut p.bytes[..OBSERVATION_LEN]) else { continue };
        if rng.random::<f64>() < faults.teleport {
            let [x, y, z] = pkt.position();
            pkt.set_position([-x, -y, z]);
            n.teleported += 1;
        }
        if jump_from.is_some_and(|j| p.at >= j) {
            let c = pkt.capture_ns();
            pkt.set_capture_ns(c.saturating_add_signed(jump_ns));
            n.clock_jumped += 1;
        }
        if rng.random::<f64>() < faults.reorder {
            p.at = p.at + secs(faults.reorder_by);
            n.reordered += 1;
        }
        if rng.random::<f64>() < faults.duplicate {
            let mut d = p;
            d.at = d.at + Duration::from_micros(50);
            out.push(d);
            n.duplicated += 1;
        }
        out.push(p);
    }
    if faults.foreign_ball {
        // The same flights mirrored across the table, 0.3 s later, own seq.
        for (k, p) in clean.iter().enumerate() {
            let Ok(pkt) = ObservationPacket::new_checked(p.bytes()) else { continue };
            let [x, y, z] = pkt.position();
            let shift = secs(0.3);
            let mut f = observation(k as u32, Instant::from_nanos(pkt.capture_ns()) + shift, [-x, -y, z]);
            f.at = p.at + shift;
            f.from = Sender::Foreign;
            out.push(f);
            n.foreign += 1;
        }
    }
    if faults.garbage_rate > 0.0 {
        let dt = 1.0 / faults.garbage_rate;
        let mut t = 0.0;
        while t <= span {
            let mut bytes = [0u8; MAX_PLANNED_LEN];
            let len = if rng.random::<f64>() < 0.5 { OBSERVATION_LEN } else { rng.random_range(0..=MAX_PLANNED_LEN) };
            rng.fill(&mut bytes[..len]);
            if len >= 4 && rng.random::<f64>() < 0.5 {
                bytes[..4].copy_from_slice(b"TTB1");
            }
            out.push(Planned { at: start + secs(t), from: Sender::Tracker, len, bytes });
            n.garbage += 1;
            t += dt;
        }
    }
    out.sort_by_key(|p| p.at);
    (out, n)
}

/// Sends `plan` in order, each datagram at its time: `Sender::Tracker`
/// ones over `tracker`, `Sender::Foreign` ones over `foreign` (skipped
/// without one). Both sockets are connected to the daemon.
pub(crate) fn send_planned(
    tracker: &UdpSocket,
    foreign: Option<&UdpSocket>,
    plan: &[Planned],
    stop: &AtomicBool,
) -> io::Result<StreamStats> {
    let mut stats = StreamStats::default();
    for p in plan {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let now = clock::now();
        if p.at > now {
            std::thread::sleep(std::time::Duration::from_nanos((p.at - now).0));
        }
        let socket = match p.from {
            Sender::Tracker => tracker,
            Sender::Foreign => match foreign {
                Some(s) => s,
                None => continue,
            },
        };
        match socket.send(p.bytes()) {
            Ok(_) => stats.sent += 1,
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => stats.refused += 1,
            Err(e) => return Err(e),
        }
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{TrackerModel, schedule};
    use topspin_core::calib::Calibration;

    fn clean() -> Vec<Planned> {
        let cal = Calibration::default_cell();
        let balls = crate::simulate_set(&cal, 3, 3, &TrackerModel::default());
        let ends: Vec<f64> = balls.iter().map(|b| b.truth.end_t).collect();
        plan_datagrams(&balls, &schedule(&ends, 1.5), 0.005, Instant::from_nanos(1_000_000_000))
    }

    #[test]
    fn no_faults_is_the_identity() {
        let c = clean();
        let (out, n) = inject(&c, &TrackerFaults::default(), 1);
        assert_eq!(out, c);
        assert_eq!(n, InjectedCounts { clean: c.len() as u64, ..Default::default() });
    }

    #[test]
    fn all_faults_happen_and_are_seeded() {
        let c = clean();
        let (a, n) = inject(&c, &TrackerFaults::all(), 5);
        let (b, _) = inject(&c, &TrackerFaults::all(), 5);
        assert_eq!(a, b);
        let share = n.lost as f64 / c.len() as f64;
        assert!((0.12..0.28).contains(&share), "{n:?}");
        for (name, k) in [
            ("silenced", n.silenced),
            ("duplicated", n.duplicated),
            ("reordered", n.reordered),
            ("garbage", n.garbage),
            ("foreign", n.foreign),
            ("teleported", n.teleported),
            ("clock_jumped", n.clock_jumped),
        ] {
            assert!(k > 0, "no {name}: {n:?}");
        }
        // Garbage at 10× a 150 Hz tracker.
        let span = (c.last().unwrap().at - c.first().unwrap().at).0 as f64 * 1e-9;
        assert!((n.garbage as f64 - 1500.0 * span).abs() < 2.0, "{n:?}");
        assert!(a.windows(2).all(|w| w[0].at <= w[1].at));
    }
}
