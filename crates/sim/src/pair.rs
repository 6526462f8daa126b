//! The mock KR C4 and the RSI session in one thread on a virtual clock,
//! the way quinn-proto's tests drive a `Pair` of connections: no sockets,
//! no threads, no sleeps. Each controller cycle is the same sequence the
//! UDP runner (`crate::mock_krc::runner`) goes through on the wall clock — the
//! request leaves at the cycle's start, reaches the sensor after the
//! link's latency, the session answers after its own processing time, the
//! answer travels back and is offered to the controller if it arrives
//! before the deadline — with the same seeded faults ([`Faults`]: drop,
//! delay and duplicate answers, reorder requests). Everything a run
//! produces is a function of its inputs and seed: tests on it assert
//! exact values.
//!
//! The sensor side is the daemon's: a latest-value plan slot
//! ([`Pair::publish`]) read when a request arrives, as `rsi_server` does,
//! and [`RsiSession::handle_timeout`] while the link is quiet.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::mock_krc::controller::{ControllerConfig, MockController, PathSample, StopReason, Verdict};
use crate::mock_krc::faults::{Faults, MAX_DATAGRAM};
use crate::mock_krc::runner::MockResult;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{RsiSession, SessionEvent};
use topspin_core::time::{Duration, Instant};

/// The link's and the sensor's timing, on the virtual clock.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LinkTiming {
    /// Request: controller → sensor.
    pub request_latency: Duration,
    /// The sensor's time from a request to its answer.
    pub processing: Duration,
    /// Answer: sensor → controller.
    pub answer_latency: Duration,
    /// An answer must arrive this long after its request left (the real
    /// controller's deadline is the cycle).
    pub deadline: Duration,
}

impl LinkTiming {
    /// A direct Ethernet link (≈ 60 µs each way, 20 µs of processing) and
    /// the controller's deadline at one cycle of `cycle_ms`.
    pub fn direct(cycle_ms: u32) -> Self {
        LinkTiming {
            request_latency: Duration::from_micros(60),
            processing: Duration::from_micros(20),
            answer_latency: Duration::from_micros(60),
            deadline: Duration::from_millis(cycle_ms as u64),
        }
    }
}

/// An answer in flight to the controller.
#[derive(Clone, Debug)]
struct InFlight {
    arrives: Instant,
    bytes: Vec<u8>,
}

/// The controller and the session, stepped one controller cycle at a time.
#[derive(Debug)]
pub struct Pair {
    /// The mock controller (its counters are public).
    pub controller: MockController,
    /// The daemon's RSI session.
    pub session: RsiSession,
    /// The link's timing.
    pub timing: LinkTiming,
    faults: Faults,
    rng: ChaCha8Rng,
    /// The start of the next controller cycle.
    now: Instant,
    /// The session's last idle call.
    last_call: Instant,
    slot: Option<StrikePlan>,
    held_request: Option<Vec<u8>>,
    in_flight: Vec<InFlight>,
    events: Vec<SessionEvent>,
    result: MockResult,
    tx: Vec<u8>,
    rx: Vec<u8>,
}

impl Pair {
    /// A pair whose first cycle starts at `t0`.
    pub fn new(session: RsiSession, controller: ControllerConfig, faults: Faults, seed: u64, t0: Instant) -> Self {
        let timing = LinkTiming::direct(controller.cycle_ms);
        Pair {
            controller: MockController::new(controller),
            session,
            timing,
            faults,
            rng: ChaCha8Rng::seed_from_u64(seed),
            now: t0,
            last_call: t0,
            slot: None,
            held_request: None,
            in_flight: Vec::new(),
            events: Vec::new(),
            result: MockResult::default(),
            tx: vec![0; MAX_DATAGRAM],
            rx: vec![0; MAX_DATAGRAM],
        }
    }

    /// The start of the next cycle on the virtual clock.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// One cycle's length.
    pub fn cycle(&self) -> Duration {
        Duration::from_millis(self.controller.config().cycle_ms as u64)
    }

    /// Publishes a plan into the latest-value slot (the estimator's side):
    /// the session takes the newest one when the next request arrives.
    pub fn publish(&mut self, plan: StrikePlan) {
        self.slot = Some(plan);
    }

    /// What the run did so far (the controller's counters and path).
    pub fn result(&self) -> MockResult {
        let c = &self.controller;
        MockResult {
            cycles: c.cycles,
            late: c.late,
            stopped_by_limit: c.stopped == Some(StopReason::LateLimit),
            stopped_by_monitor: c.stopped == Some(StopReason::Monitor),
            wrong_ipoc: c.wrong_ipoc,
            wrong_type: c.wrong_type,
            malformed: c.malformed,
            poscorr_clamped: c.poscorr_clamped,
            axiscorr_clamped: c.axiscorr_clamped,
            wrong_kind: c.wrong_kind,
            akorr_range_deg: c.akorr_range_deg,
            stopped: c.stopped,
            peak_speed_share: c.peak_speed_share,
            peak_acceleration_share: c.peak_acceleration_share,
            rates_over: c.rates_over,
            ..self.result.clone()
        }
    }

    /// The controller's path so far, one sample a cycle.
    pub fn path(&self) -> &[PathSample] {
        &self.result.path
    }

    /// The session's events so far, oldest first (drained).
    pub fn take_events(&mut self) -> Vec<SessionEvent> {
        std::mem::take(&mut self.events)
    }

    /// Runs one controller cycle; `None` once RSI has stopped.
    pub fn step(&mut self) -> Option<PathSample> {
        if self.controller.stopped.is_some() {
            return None;
        }
        let t_k = self.now;
        let cycle = self.cycle();
        let n = self.controller.request(&mut self.tx).expect("a request fits the datagram buffer");
        let request = self.tx[..n].to_vec();
        let arrival = t_k + self.timing.request_latency;
        if let Some(older) = self.held_request.take() {
            // The held request goes out after this newer one.
            self.deliver_request(arrival, &request);
            self.deliver_request(arrival, &older);
        } else if self.faults.reorder > 0.0 && self.rng.random::<f64>() < self.faults.reorder {
            self.result.reordered += 1;
            self.held_request = Some(request);
        } else {
            self.deliver_request(arrival, &request);
        }
        let deadline = t_k + self.timing.deadline;
        self.in_flight.sort_by_key(|a| a.arrives);
        while let Some(k) = self.in_flight.iter().position(|a| a.arrives <= deadline) {
            let a = self.in_flight.remove(k);
            if self.controller.answer(&a.bytes) == Verdict::Accepted {
                let d = a.arrives - t_k;
                self.result.max_answer_delay = self.result.max_answer_delay.max(d);
                if d > cycle {
                    self.result.answers_after_cycle += 1;
                }
                break;
            }
        }
        let next = t_k + cycle;
        let sample = self.controller.end_cycle(next);
        self.result.path.push(sample);
        self.idle_until(next);
        Some(sample)
    }

    /// Runs `n` cycles (fewer if RSI stops); the number run.
    pub fn run(&mut self, n: u64) -> u64 {
        (0..n).take_while(|_| self.step().is_some()).count() as u64
    }

    /// Publishes the strike stream (`crate::strikes`, seeded with `seed`)
    /// on the virtual clock from now for `n` cycles, each plan at its
    /// `made_at`; the plans committed.
    pub fn run_strikes(&mut self, seed: u64, n: u64) -> Vec<StrikePlan> {
        let end = self.now + Duration::from_millis(n * self.controller.config().cycle_ms as u64);
        let mut finals = Vec::new();
        for r in crate::strikes::strike_stream(seed, self.now, end) {
            while self.now < r.plan.made_at {
                self.step().expect("RSI running");
            }
            self.publish(r.plan);
            if r.committed {
                finals.push(r.plan);
            }
        }
        while self.now < end {
            self.step().expect("RSI running");
        }
        finals
    }

    /// RSI is off for `gap` (no requests; the session sees silence), then
    /// the controller starts a fresh RSI run with `controller`: its IPOC,
    /// cycle and start pose. Answers still in flight are lost with the old
    /// run; the path log goes on.
    pub fn restart(&mut self, gap: Duration, controller: ControllerConfig) {
        self.idle_until(self.now + gap);
        self.in_flight.clear();
        self.held_request = None;
        self.timing.deadline = Duration::from_millis(controller.cycle_ms as u64);
        self.controller = MockController::new(controller);
    }

    /// The session's idle calls (as the server makes while `recv` times
    /// out), every millisecond up to `until`.
    fn idle_until(&mut self, until: Instant) {
        let mut t = self.last_call;
        while t < until {
            t = (t + Duration::from_millis(1)).min(until);
            self.session.handle_timeout(t);
            self.drain_events();
        }
        self.last_call = until;
        self.now = until;
    }

    fn drain_events(&mut self) {
        while let Some(e) = self.session.poll_event() {
            self.events.push(e);
        }
    }

    /// The sensor receives a request at `at` and answers it.
    fn deliver_request(&mut self, at: Instant, bytes: &[u8]) {
        self.session.handle_timeout(at);
        if let Some(p) = self.slot.take() {
            self.session.set_plan(p);
        }
        if let Ok(n) = self.session.handle_datagram(at, bytes, &mut self.rx) {
            let sent = at + self.timing.processing;
            self.session.answer_sent(sent);
            let arrives = sent + self.timing.answer_latency;
            let bytes = self.rx[..n].to_vec();
            let roll: f64 = self.rng.random();
            let f = self.faults;
            if roll < f.drop {
                self.result.dropped += 1;
            } else if roll < f.drop + f.delay {
                self.result.delayed += 1;
                self.in_flight.push(InFlight { arrives: arrives + f.delay_by, bytes });
            } else if roll < f.drop + f.delay + f.duplicate {
                self.result.duplicated += 1;
                self.in_flight.push(InFlight { arrives, bytes: bytes.clone() });
                self.in_flight.push(InFlight { arrives, bytes });
            } else {
                self.in_flight.push(InFlight { arrives, bytes });
            }
        }
        self.drain_events();
    }
}
