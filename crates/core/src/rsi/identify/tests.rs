//! The identifier against an in-memory robot with a known dead time and
//! lag, on a virtual clock, through the real codec both ways.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use std::collections::VecDeque;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::*;
use crate::rsi::codec::{RobElement, SenFrame};

const START: [f64; 6] = [350.0, 0.0, 450.0, 180.0, 0.0, 0.0];
const WITH_DELAY: [RobElement; 3] = [RobElement::RIst, RobElement::RSol, RobElement::Delay];
const WITHOUT_DELAY: [RobElement; 2] = [RobElement::RIst, RobElement::RSol];

/// What goes wrong on the link, per cycle, seeded.
#[derive(Copy, Clone, Debug, Default)]
struct Faults {
    /// The request never arrives (the controller counts the cycle late).
    drop: f64,
    /// The request arrives after the cycle's deadline (answer late).
    late: f64,
    /// The request arrives twice.
    repeat: f64,
    /// The request arrives after the next one (its answer is late).
    reorder: f64,
}

/// The robot: a correction answered for request k is applied at the end
/// of cycle k, reaches the servo `d` cycles later, and the TCP follows it
/// with a first-order lag (exact for a correction held over the cycle).
struct Plant {
    tau: f64,
    /// A second lag after the first (0: none): a servo the model does not
    /// describe exactly.
    tau2: f64,
    gain: f64,
    cycle_ms: u32,
    noise: f64,
    send: &'static [RobElement],
    ipoc: u64,
    correction: [f64; 3],
    line: VecDeque<[f64; 3]>,
    y: [f64; 3],
    y1: [f64; 3],
    late: u64,
    answered: Option<[f64; 3]>,
    /// The correction applied in each cycle.
    applied: Vec<[f64; 3]>,
    rng: ChaCha8Rng,
}

impl Plant {
    fn new(d: usize, tau: f64, noise: f64, seed: u64) -> Self {
        Plant {
            tau,
            tau2: 0.0,
            gain: 1.0,
            cycle_ms: 4,
            noise,
            send: &WITH_DELAY,
            ipoc: 4_208_831,
            correction: [0.0; 3],
            line: VecDeque::from(vec![[0.0; 3]; d]),
            y: [0.0; 3],
            y1: [0.0; 3],
            late: 0,
            answered: None,
            applied: Vec::new(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    fn request(&mut self, buf: &mut [u8]) -> usize {
        let normal = Normal::new(0.0, self.noise.max(1e-300)).unwrap();
        let mut p = START;
        for i in 0..3 {
            p[i] += self.y[i] + if self.noise > 0.0 { normal.sample(&mut self.rng) } else { 0.0 };
        }
        let pose = KukaPose::from_array(p);
        RobFrame {
            ipoc: self.ipoc,
            rist: Some(pose),
            rsol: Some(pose),
            aipos: None,
            aspos: None,
            delay: Some(self.late),
        }
        .emit(self.send, 4, buf)
        .unwrap()
    }

    fn answer(&mut self, bytes: &[u8]) {
        let s = SenFrame::parse(bytes).unwrap();
        assert_eq!(s.sentype, b"ImFree");
        if s.ipoc == self.ipoc && self.answered.is_none() {
            let k = s.rkorr.unwrap();
            self.answered = Some([k.x, k.y, k.z]);
        }
    }

    fn end_cycle(&mut self) {
        match self.answered.take() {
            Some(k) => self.correction = k,
            None => self.late += 1,
        }
        self.applied.push(self.correction);
        self.line.push_back(self.correction);
        let u = self.line.pop_front().unwrap();
        let dt = self.cycle_ms as f64 * 1e-3;
        let a = if self.tau > 0.0 { (-dt / self.tau).exp() } else { 0.0 };
        if self.tau2 > 0.0 {
            // Two lags in series, integrated finely within the cycle.
            let steps = 64;
            let h = dt / steps as f64;
            for _ in 0..steps {
                for i in 0..3 {
                    self.y1[i] += h * (self.gain * u[i] - self.y1[i]) / self.tau;
                    self.y[i] += h * (self.y1[i] - self.y[i]) / self.tau2;
                }
            }
        } else {
            for i in 0..3 {
                self.y[i] = a * self.y[i] + (1.0 - a) * self.gain * u[i];
            }
        }
        self.ipoc += self.cycle_ms as u64;
    }
}

fn identifier(axes: AxisChoice, seconds: f64) -> Identifier {
    let exc = Excitation::new(ExcitationConfig { amplitude_mm: 3.0, axes, seconds, cycle_ms: 4 }).unwrap();
    let cfg = IdentifierConfig::from_calibration(&Calibration::default_cell(), "ImFree");
    Identifier::new(cfg, exc).unwrap()
}

/// Runs the plant against the identifier for the excitation and half a
/// second more, on a virtual clock: requests arrive 100 µs into their
/// cycle (5 ms, after the deadline, when late).
fn run(plant: &mut Plant, id: &mut Identifier, faults: Faults, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut rx = [0u8; 1024];
    let mut tx = [0u8; 1024];
    let mut answers = Vec::new();
    let mut held: Option<(Vec<u8>, u64)> = None;
    let cycles = id.excitation().len() + 125;
    for k in 0..cycles as u64 {
        let t = 1_000_000_000 + k * plant.cycle_ms as u64 * 1_000_000;
        let n = plant.request(&mut rx);
        let req = rx[..n].to_vec();
        let mut deliver = |bytes: &[u8], at: u64, plant: &mut Plant, on_time: bool| {
            let len = id.handle_datagram(Instant(at), bytes, &mut tx).unwrap();
            id.answer_sent(Instant(at + 20_000));
            let s = SenFrame::parse(&tx[..len]).unwrap();
            assert_eq!(s.ipoc, RobFrame::parse(bytes).unwrap().ipoc, "IPOC echoed");
            let k = s.rkorr.unwrap();
            answers.push([k.x, k.y, k.z]);
            if on_time {
                plant.answer(&tx[..len]);
            }
        };
        let r: f64 = rng.random();
        if r < faults.drop {
        } else if r < faults.drop + faults.late {
            deliver(&req, t + 5_000_000, plant, false);
        } else if r < faults.drop + faults.late + faults.reorder && held.is_none() {
            held = Some((req, t));
        } else {
            deliver(&req, t + 100_000, plant, true);
            if rng.random::<f64>() < faults.repeat {
                deliver(&req, t + 150_000, plant, false);
            }
        }
        if let Some((bytes, t0)) = held.take_if(|(_, t0)| *t0 < t) {
            deliver(&bytes, t + 200_000, plant, false);
            let _ = t0;
        }
        plant.end_cycle();
    }
    answers
}

fn check(id: &Identifier, d: usize, tau: f64, tol: f64) -> Identification {
    let r = id.finish().unwrap_or_else(|e| panic!("d {d} τ {tau}: {e}"));
    eprintln!(
        "plant d {d} τ {:.1} ms → d {} (± {:.2} ms, runner-up {} ×{:.2}) τ {:.2} ± {:.2} ms, rms {:.4} mm, fit {:.2} %, late {} gaps {}",
        tau * 1e3,
        r.fit.dead_time_cycles,
        r.dead_time_std_ms,
        r.fit.runner_up_cycles,
        r.fit.runner_up_ratio,
        r.lag_ms,
        r.lag_std_ms,
        r.fit.rms_mm,
        r.fit.fit_percent,
        r.late,
        r.gaps
    );
    assert_eq!(r.fit.dead_time_cycles, d, "{r:#?}");
    assert_eq!(r.dead_time_ms, d as f64 * 4.0);
    // Below an eighth of a cycle τ changes the response by < 0.1 %: not
    // resolved.
    assert!((r.lag_ms - tau * 1e3).abs() <= tol * tau * 1e3 + 0.5, "τ {} ms vs {} ms", r.lag_ms, tau * 1e3);
    r
}

#[test]
fn recovers_the_plant_exactly_without_noise() {
    for (d, tau) in [(0, 0.004), (3, 0.015), (1, 0.030), (6, 0.008), (2, 0.0)] {
        let mut p = Plant::new(d, tau, 0.0, 1);
        let mut id = identifier(AxisChoice::X, 4.0);
        run(&mut p, &mut id, Faults::default(), 1);
        let r = check(&id, d, tau, 0.01);
        assert!(r.fit.fit_percent > 99.9 && r.fit.rms_mm < 1e-3, "{r:#?}");
        assert_eq!((r.late, r.gaps), (0, 0));
        assert!((r.fit.gain[0].unwrap() - 1.0).abs() < 1e-3);
        assert!(!r.off_home);
    }
}

#[test]
fn recovers_it_through_noise_on_every_axis() {
    for (d, tau, seed) in [(3, 0.015, 1), (1, 0.030, 2), (4, 0.012, 3)] {
        let mut p = Plant::new(d, tau, 0.03, seed);
        let mut id = identifier(AxisChoice::All, 9.0);
        run(&mut p, &mut id, Faults::default(), seed);
        let r = check(&id, d, tau, 0.05);
        assert!((r.lag_ms - tau * 1e3).abs() < 4.0 * r.lag_std_ms, "{} ± {} vs {tau}", r.lag_ms, r.lag_std_ms);
        assert!(r.fit.runner_up_ratio > 1.1, "{r:#?}");
        assert!(r.dead_time_std_ms < 1.0, "{r:#?}");
        for i in 0..3 {
            let t = r.fit.lag_s_per_axis[i].unwrap();
            assert!((t - tau).abs() < 0.1 * tau, "axis {i}: {t}");
        }
        // The lead-in sees the noise, the fit's residual too.
        assert!((r.rist_noise_mm - 0.03).abs() < 0.01, "{}", r.rist_noise_mm);
        assert!((r.fit.rms_mm - 0.03).abs() < 0.005, "{}", r.fit.rms_mm);
    }
}

#[test]
fn survives_lost_late_repeated_and_reordered_requests() {
    for (send, seed) in [(&WITH_DELAY[..], 5), (&WITHOUT_DELAY[..], 6)] {
        let mut p = Plant::new(3, 0.015, 0.02, seed);
        p.send = send;
        let mut id = identifier(AxisChoice::Y, 5.0);
        let faults = Faults { drop: 0.04, late: 0.03, repeat: 0.02, reorder: 0.02 };
        let answers = run(&mut p, &mut id, faults, seed);
        let r = check(&id, 3, 0.015, 0.05);
        let s = r.stats;
        assert!(s.ipoc_gaps > 20 && s.ipoc_repeats > 10 && s.stale > 10, "{s:?}");
        // The corrections rebuilt are the ones the robot applied, cycle by
        // cycle (the last one's fate is unknown until the next request).
        let (trace, late) = id.trace();
        assert_eq!(late, r.late);
        let n = trace.u.len() - 1;
        let wrong = (0..n).filter(|k| trace.u[*k] != p.applied[*k]).count();
        assert_eq!(wrong, 0, "{wrong} of {n} cycles rebuilt wrong");
        assert!(late > 50 && r.gaps > 20, "{late} {}", r.gaps);
        // Never a jump between two answers, gaps or not.
        for w in answers.windows(2) {
            for i in 0..3 {
                assert!((w[1][i] - w[0][i]).abs() <= id.excitation().max_step_mm() + 1e-4, "{w:?}");
            }
        }
    }
}

#[test]
fn ignoring_late_answers_would_have_cost_accuracy() {
    // The same faults, with the trace's late cycles treated as applied:
    // the fit is worse, so the reconstruction matters.
    let mut p = Plant::new(2, 0.020, 0.0, 9);
    let mut id = identifier(AxisChoice::Z, 5.0);
    run(&mut p, &mut id, Faults { late: 0.08, ..Faults::default() }, 9);
    let good = id.finish().unwrap();
    assert!(good.fit.rms_mm < 1e-3, "{}", good.fit.rms_mm);
    let (mut naive, _) = id.trace();
    let mut last = [0.0; 3];
    for (n, u) in naive.u.iter_mut().enumerate() {
        *u = id.log[n].sent.unwrap_or(last);
        last = *u;
    }
    let bad = fit::fit(&naive, 30).unwrap();
    assert!(bad.rms_mm > 20.0 * good.fit.rms_mm.max(1e-4), "{} vs {}", bad.rms_mm, good.fit.rms_mm);
}

#[test]
fn a_second_order_servo_keeps_its_total_delay() {
    // Not the model: two lags (10 and 5 ms) after 2 cycles. The fit is
    // still good, and its total delay d·T + τ is the plant's mean delay
    // 2·T + τ₁ + τ₂ = 23 ms within one cycle.
    let mut p = Plant::new(2, 0.010, 0.02, 4);
    p.tau2 = 0.005;
    let mut id = identifier(AxisChoice::X, 5.0);
    run(&mut p, &mut id, Faults::default(), 4);
    let r = id.finish().unwrap();
    let total = r.dead_time_ms + r.lag_ms;
    eprintln!(
        "two lags 10 + 5 ms after 2 cycles → d {} τ {:.2} ms, total {total:.2} ms, fit {:.2} %, rms {:.4} mm",
        r.fit.dead_time_cycles, r.lag_ms, r.fit.fit_percent, r.fit.rms_mm
    );
    assert!((total - 23.0).abs() < 4.0, "{total}");
    assert!(r.fit.fit_percent > 95.0, "{}", r.fit.fit_percent);
}

#[test]
fn a_robot_that_does_not_move_is_refused() {
    let mut p = Plant::new(2, 0.015, 0.02, 1);
    p.gain = 0.0;
    let mut id = identifier(AxisChoice::X, 4.0);
    run(&mut p, &mut id, Faults::default(), 1);
    let e = id.finish().unwrap_err();
    assert!(matches!(e, IdentifyError::DidNotMove { axis: 'x', .. }), "{e}");
    assert!(e.to_string().starts_with("the robot did not move on x"), "{e}");
    // Half the motion: a gain the fit sees and refuses.
    let mut p = Plant::new(2, 0.015, 0.0, 1);
    p.gain = 0.5;
    let mut id = identifier(AxisChoice::X, 4.0);
    run(&mut p, &mut id, Faults::default(), 1);
    assert!(matches!(id.finish(), Err(IdentifyError::Gain { axis: 'x', gain }) if (gain - 0.5).abs() < 0.01));
}

#[test]
fn protocol_rules_match_the_session() {
    let mut id = identifier(AxisChoice::X, 4.0);
    let mut p = Plant::new(0, 0.0, 0.0, 1);
    let mut rx = [0u8; 1024];
    let mut tx = [0u8; 1024];
    assert_eq!(id.finish(), Err(IdentifyError::NoRequests));
    assert!(matches!(id.handle_datagram(Instant(0), b"<Sen/>", &mut tx), Err(SessionError::Malformed(_))));
    assert_eq!(id.stats().malformed, 1);
    // Run into the first step, then repeat a request and skip 20 cycles.
    let mut last = [0.0; 3];
    for k in 0..80u64 {
        let n = p.request(&mut rx);
        let len = id.handle_datagram(Instant(k * 4_000_000), &rx[..n], &mut tx).unwrap();
        let s = SenFrame::parse(&tx[..len]).unwrap();
        assert_eq!(s.ipoc, 4_208_831 + 4 * k);
        assert_eq!(s.estr, Some(&b"topspin identify"[..]));
        last = [s.rkorr.unwrap().x, 0.0, 0.0];
        if k == 79 {
            let again = id.handle_datagram(Instant(k * 4_000_000 + 1), &rx[..n], &mut tx).unwrap();
            assert_eq!(SenFrame::parse(&tx[..again]).unwrap().rkorr.unwrap().x, last[0], "repeat: same answer");
            assert_eq!(id.stats().ipoc_repeats, 1);
        }
        p.answer(&tx[..len]);
        p.end_cycle();
    }
    assert!(last[0] > 0.0 && id.state() == IdentifierState::Exciting);
    for _ in 0..20 {
        p.end_cycle();
    }
    let n = p.request(&mut rx);
    let len = id.handle_datagram(Instant(400_000_000), &rx[..n], &mut tx).unwrap();
    let x = SenFrame::parse(&tx[..len]).unwrap().rkorr.unwrap().x;
    assert!((x - last[0]).abs() <= id.excitation().max_step_mm() + 1e-9, "{x} after {}", last[0]);
    assert_eq!(id.stats().ipoc_gaps, 1);
    assert_eq!(id.cycle(), 100);
    // RSI started again (IPOC from before the start): the excitation too.
    let mut q = Plant::new(0, 0.0, 0.0, 1);
    q.ipoc = 1000;
    let n = q.request(&mut rx);
    let len = id.handle_datagram(Instant(500_000_000), &rx[..n], &mut tx).unwrap();
    assert_eq!(SenFrame::parse(&tx[..len]).unwrap().rkorr.unwrap().x, 0.0);
    assert_eq!((id.stats().restarts, id.cycle(), id.stats().requests), (1, 0, 1));
}

#[test]
fn a_short_run_and_a_blind_robot_are_refused() {
    // The controller stops after a second of four.
    let mut p = Plant::new(1, 0.01, 0.0, 1);
    let mut id = identifier(AxisChoice::X, 4.0);
    let mut rx = [0u8; 1024];
    let mut tx = [0u8; 1024];
    for k in 0..250u64 {
        let n = p.request(&mut rx);
        let len = id.handle_datagram(Instant(k * 4_000_000), &rx[..n], &mut tx).unwrap();
        p.answer(&tx[..len]);
        p.end_cycle();
    }
    assert_eq!(id.finish(), Err(IdentifyError::Truncated { cycles: 250, expected: 1000 }));
    // No RIst in the SEND list: never moves, says why.
    let mut p = Plant::new(1, 0.01, 0.0, 1);
    p.send = &[RobElement::Delay];
    let mut id = identifier(AxisChoice::X, 4.0);
    let answers = run(&mut p, &mut id, Faults::default(), 1);
    assert!(answers.iter().all(|a| *a == [0.0; 3]));
    assert_eq!(id.finish(), Err(IdentifyError::NoRist));
    // The controller runs at 12 ms while the calibration says 4.
    let mut p = Plant::new(1, 0.01, 0.0, 1);
    p.cycle_ms = 12;
    let mut id = identifier(AxisChoice::X, 4.0);
    run(&mut p, &mut id, Faults::default(), 1);
    assert_eq!(id.finish(), Err(IdentifyError::IpocStep { step_ms: 12, cycle_ms: 4 }));
}
