//! The mock's UDP loop: sends `<Rob>` on an absolute schedule (sleep until
//! ~300 µs early, then spin: DESIGN §10), collects the answer until the
//! cycle's deadline, closes the cycle, logs the path. In process on a
//! thread ([`spawn`]) or blocking ([`run`]).

use std::collections::VecDeque;
use std::io;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::config::{ContextConfig, EthernetConfig, RsiFileError};
use super::controller::{ControllerConfig, CorrMode, MockController, PathSample, StopReason, Verdict};
use super::faults::{FaultInjector, Faults, Link, MAX_DATAGRAM, UdpLink};
use topspin_core::calib::RobotFile;
use topspin_core::rsi::Correction;
use topspin_core::time::{Duration, Instant};
use topspin_daemon::clock::{self, SPIN_BEFORE_DEADLINE};
use topspin_daemon::runtime::ThreadSpec;
use topspin_daemon::runtime::rt::{self, RtWarning};

/// How the mock runs.
#[derive(Clone, Debug, PartialEq)]
pub struct MockKrcConfig {
    /// The controller model's setup.
    pub controller: ControllerConfig,
    /// The sensor's address (Ethernet XML IP_NUMBER:PORT unless overridden).
    pub sensor: SocketAddr,
    /// The mock's own address.
    pub bind: SocketAddr,
    /// Stop after this many cycles (`None`: until stopped).
    pub cycles: Option<u64>,
    /// An answer must arrive within this time after the request. The real
    /// controller's deadline is the cycle (the default, less 200 µs for the
    /// mock's own scheduling). Tests on a loaded shared machine may stretch
    /// it beyond the cycle: the next request then waits (the schedule slips
    /// and catches up), and answers later than one cycle are still counted
    /// in `MockResult::answers_after_cycle`.
    pub answer_deadline: Duration,
    /// Faults injected on the link (default: none).
    pub faults: Faults,
    /// Seed of the fault injector's random stream.
    pub seed: u64,
    /// The mock thread's core and SCHED_FIFO priority ([`spawn`] only;
    /// default: neither). `topspin bench latency --layout dedicated` gives
    /// it a core of its own, as the real controller has its own hardware.
    pub thread: ThreadSpec,
}

impl MockKrcConfig {
    /// From the controller-side files and the robot cell: start at home
    /// (in the home joints), the arm's axis limits scaled by
    /// `robot_margin` (1.0: the robot is what the calibration says), the
    /// calibration's dead time and lag; the correction (RKorr or AKorr)
    /// the Ethernet configuration receives (see
    /// [`ContextConfig::check_feeds`]).
    pub fn from_files(
        ethernet: &EthernetConfig,
        context: &ContextConfig,
        robot: &RobotFile,
        mode: CorrMode,
        robot_margin: f64,
    ) -> Self {
        let mut arm = robot.arm();
        arm.limits.speed = arm.limits.speed.map(|x| x * robot_margin);
        arm.limits.acceleration = arm.limits.acceleration.map(|x| x * robot_margin);
        let h = &robot.home;
        let controller = ControllerConfig {
            cycle_ms: robot.rsi.cycle_ms,
            mode,
            correction: ethernet.correction(),
            sentype: ethernet.sentype.clone(),
            precision: context.precision,
            send: ethernet.send.clone(),
            late_limit: context.timeout as u64,
            start: [h.xyz_m[0] * 1e3, h.xyz_m[1] * 1e3, h.xyz_m[2] * 1e3, h.abc_deg[0], h.abc_deg[1], h.abc_deg[2]],
            start_joints: robot.home_joints(&arm).expect("a validated robot.toml has home joints"),
            arm,
            dead_time_cycles: robot.servo.dead_time_cycles(robot.rsi.cycle_ms),
            lag_s: robot.servo.lag_s(),
            stop_on_axis_rates: false,
            lower_mm: context.lower_mm,
            upper_mm: context.upper_mm,
            max_rot_deg: context.max_rot_deg,
            mon_max_trans_mm: context.mon_max_trans_mm,
            mon_max_rot_deg: context.mon_max_rot_deg,
            axis_lower_deg: context.axis_lower_deg,
            axis_upper_deg: context.axis_upper_deg,
            axis_mon_max_deg: context.axis_mon_max_deg,
            first_ipoc: 4_208_831,
            base: topspin_core::kinematics::Pose::identity(),
            brakes: None,
        };
        MockKrcConfig {
            controller,
            sensor: ethernet.sensor_addr(),
            bind: "0.0.0.0:0".parse().expect("literal"),
            cycles: None,
            answer_deadline: Duration::from_millis(robot.rsi.cycle_ms as u64),
            faults: Faults::default(),
            seed: 1,
            thread: ThreadSpec::default(),
        }
    }

    /// From the compiled-in Cartesian `rsi/` files and calibration.
    pub fn default_cell() -> Result<Self, RsiFileError> {
        Self::default_cell_for(Correction::Cartesian)
    }

    /// From the compiled-in `rsi/` files of `correction` (the Cartesian
    /// or the axis pair) and calibration.
    pub fn default_cell_for(correction: Correction) -> Result<Self, RsiFileError> {
        let [(_, ethernet), (_, context)] = super::config::rsi_files(correction);
        let e = EthernetConfig::parse(ethernet)?;
        let c = ContextConfig::parse(context)?;
        c.check_feeds(&e)?;
        let r = topspin_core::calib::Calibration::default_cell().robot;
        Ok(Self::from_files(&e, &c, &r, CorrMode::Absolute, 1.0))
    }
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MockResult {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles without a valid answer by the deadline (= final `<Delay>`).
    pub late: u64,
    /// RSI stopped at the Timeout limit of late answers.
    pub stopped_by_limit: bool,
    /// RSI stopped by POSCORRMON (the correction too large).
    pub stopped_by_monitor: bool,
    /// Answers refused for an IPOC other than their cycle's.
    pub wrong_ipoc: u64,
    /// Answers refused for a `Type` other than SENTYPE.
    pub wrong_type: u64,
    /// Datagrams that did not parse as `<Sen>`.
    pub malformed: u64,
    /// Cycles whose RKorr POSCORR clamped.
    pub poscorr_clamped: u64,
    /// Cycles whose AKorr AXISCORR clamped (axis context).
    pub axiscorr_clamped: u64,
    /// On-time answers carrying only the other kind of correction (held).
    pub wrong_kind: u64,
    /// The smallest and largest AKorr asked per axis, degrees (axis
    /// context; zeros otherwise).
    pub akorr_range_deg: [[f64; 2]; 6],
    /// Why the controller stopped RSI, if it did.
    pub stopped: Option<StopReason>,
    /// The fastest and hardest any axis moved, as shares of its limits.
    pub peak_speed_share: f64,
    /// The hardest any axis accelerated, as a share of its acceleration limit.
    pub peak_acceleration_share: f64,
    /// Cycles with an axis over its speed or acceleration limit.
    pub rates_over: u64,
    /// Answers the fault injector dropped (`Faults::drop`).
    pub dropped: u64,
    /// Answers it held back (`Faults::delay`).
    pub delayed: u64,
    /// Answers it delivered twice (`Faults::duplicate`).
    pub duplicated: u64,
    /// Requests sent after the next one (`Faults::reorder`).
    pub reordered: u64,
    /// Latest answer arrival after its request's scheduled time.
    pub max_answer_delay: Duration,
    /// Accepted answers that came later than one cycle (only possible with
    /// a stretched `answer_deadline`).
    pub answers_after_cycle: u64,
    /// The logged TCP path, one sample per cycle.
    pub path: Vec<PathSample>,
    /// What the OS refused of [`MockKrcConfig::thread`].
    pub rt_warnings: Vec<RtWarning>,
}

impl MockResult {
    /// Writes the path as CSV: time, IPOC, on time, commanded and actual
    /// pose, actual joints.
    pub fn write_csv(&self, path: &Path) -> io::Result<()> {
        let mut w = csv::Writer::from_path(path)?;
        w.write_record([
            "t_s",
            "ipoc",
            "on_time",
            "cmd_x_mm",
            "cmd_y_mm",
            "cmd_z_mm",
            "cmd_a_deg",
            "cmd_b_deg",
            "cmd_c_deg",
            "act_x_mm",
            "act_y_mm",
            "act_z_mm",
            "act_a_deg",
            "act_b_deg",
            "act_c_deg",
            "a1_deg",
            "a2_deg",
            "a3_deg",
            "a4_deg",
            "a5_deg",
            "a6_deg",
        ])?;
        for s in &self.path {
            let mut rec = vec![format!("{:.6}", s.t.as_secs_f64()), s.ipoc.to_string(), (s.on_time as u8).to_string()];
            rec.extend(s.commanded.iter().map(|x| format!("{x:.4}")));
            rec.extend(s.actual.iter().map(|x| format!("{x:.4}")));
            rec.extend(s.joints.iter().map(|x| format!("{x:.4}")));
            w.write_record(&rec)?;
        }
        w.flush()
    }
}

/// A mock running on its own thread.
#[derive(Debug)]
pub struct MockHandle {
    /// Set to true to stop the mock before its next cycle.
    pub stop: Arc<AtomicBool>,
    /// The mock's own UDP address (where its requests come from).
    pub local_addr: SocketAddr,
    jog: Arc<JogPort>,
    join: JoinHandle<io::Result<MockResult>>,
}

/// Cycles of the path a running mock keeps for its owner (0.5 s at 4 ms).
const RECENT_PATH: usize = 128;

/// Between a running mock and its owner: a move asked for (taken at the
/// next cycle's start), the actual pose after the last cycle and the
/// last [`RECENT_PATH`] cycles of the path.
#[derive(Debug, Default)]
struct JogPort {
    to: Mutex<Option<[f64; 6]>>,
    actual: Mutex<Option<[f64; 6]>>,
    recent: Mutex<VecDeque<PathSample>>,
}

impl MockHandle {
    /// Asks the mock to stop and waits for its result.
    pub fn stop(self) -> io::Result<MockResult> {
        self.stop.store(true, Ordering::Relaxed);
        self.join()
    }

    /// Moves the robot to `pose` (mm, degrees) as its program or the jog
    /// keys would, RSI still running ([`MockController::move_start`]).
    pub fn move_to(&self, pose: [f64; 6]) {
        *self.jog.to.lock().unwrap_or_else(|e| e.into_inner()) = Some(pose);
    }

    /// The actual pose (`RIst`) after the last cycle, `None` before the first.
    pub fn actual(&self) -> Option<[f64; 6]> {
        *self.jog.actual.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The path's last cycles (at most 0.5 s), oldest first.
    pub fn recent_path(&self) -> Vec<PathSample> {
        self.jog.recent.lock().unwrap_or_else(|e| e.into_inner()).iter().copied().collect()
    }

    /// Waits for the mock to finish by itself (cycle count, stop by limit).
    pub fn join(self) -> io::Result<MockResult> {
        self.join.join().unwrap_or_else(|_| Err(io::Error::other("mock thread panicked")))
    }
}

/// Starts the mock on a thread.
pub fn spawn(cfg: MockKrcConfig) -> io::Result<MockHandle> {
    let link = UdpLink::new(cfg.bind, cfg.sensor)?;
    let local_addr = link.local_addr()?;
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let jog = Arc::new(JogPort::default());
    let j = jog.clone();
    let join = std::thread::Builder::new().name("mock-krc".into()).spawn(move || {
        let refused = rt::setup_current("mock-krc", cfg.thread.core, cfg.thread.priority);
        let mut r = run_on(link, &cfg, &s, Some(&j))?;
        r.rt_warnings = refused;
        Ok(r)
    })?;
    Ok(MockHandle { stop, local_addr, jog, join })
}

/// Runs the mock on this thread until `stop`, the cycle count or RSI stops.
pub fn run(cfg: &MockKrcConfig, stop: &AtomicBool) -> io::Result<MockResult> {
    run_on(UdpLink::new(cfg.bind, cfg.sensor)?, cfg, stop, None)
}

fn run_on(link: UdpLink, cfg: &MockKrcConfig, stop: &AtomicBool, jog: Option<&JogPort>) -> io::Result<MockResult> {
    if cfg.faults.any() {
        let mut f = FaultInjector::new(link, cfg.faults, cfg.seed);
        let mut r = cycle_loop(&mut f, cfg, stop, jog)?;
        r.dropped = f.dropped;
        r.delayed = f.delayed;
        r.duplicated = f.duplicated;
        r.reordered = f.reordered;
        Ok(r)
    } else {
        let mut l = link;
        cycle_loop(&mut l, cfg, stop, jog)
    }
}

fn cycle_loop<L: Link>(
    link: &mut L,
    cfg: &MockKrcConfig,
    stop: &AtomicBool,
    jog: Option<&JogPort>,
) -> io::Result<MockResult> {
    let mut ctrl = MockController::new(cfg.controller.clone());
    let cycle = Duration::from_millis(cfg.controller.cycle_ms as u64);
    let deadline_after = if cfg.answer_deadline >= cycle {
        if cfg.answer_deadline == cycle { Duration(cycle.0.saturating_sub(200_000)) } else { cfg.answer_deadline }
    } else {
        cfg.answer_deadline
    };
    let mut out = MockResult::default();
    if let Some(n) = cfg.cycles {
        out.path.reserve(n as usize);
    }
    let mut tx = [0u8; MAX_DATAGRAM];
    let mut rx = [0u8; MAX_DATAGRAM];
    let t0 = clock::now() + Duration::from_millis(2);
    let mut k: u64 = 0;
    while !stop.load(Ordering::Relaxed) && cfg.cycles.is_none_or(|n| k < n) && ctrl.stopped.is_none() {
        let t_k = Instant(t0.0 + k * cycle.0);
        clock::sleep_until(t_k, SPIN_BEFORE_DEADLINE);
        if let Some(to) = jog.and_then(|j| j.to.lock().unwrap_or_else(|e| e.into_inner()).take()) {
            ctrl.move_start(to);
        }
        let n = ctrl.request(&mut tx).map_err(|e| io::Error::other(e.to_string()))?;
        link.send(&tx[..n])?;
        let deadline = t_k + deadline_after;
        while let Some(m) = link.recv_until(deadline, &mut rx)? {
            if ctrl.answer(&rx[..m]) == Verdict::Accepted {
                let d = clock::now() - t_k;
                out.max_answer_delay = out.max_answer_delay.max(d);
                if d > cycle {
                    out.answers_after_cycle += 1;
                }
                break;
            }
        }
        let sample = ctrl.end_cycle(t_k + cycle);
        if let Some(j) = jog {
            *j.actual.lock().unwrap_or_else(|e| e.into_inner()) = Some(sample.actual);
            let mut recent = j.recent.lock().unwrap_or_else(|e| e.into_inner());
            if recent.len() == RECENT_PATH {
                recent.pop_front();
            }
            recent.push_back(sample);
        }
        out.path.push(sample);
        k += 1;
    }
    out.cycles = ctrl.cycles;
    out.late = ctrl.late;
    out.stopped_by_limit = ctrl.stopped == Some(StopReason::LateLimit);
    out.stopped_by_monitor = ctrl.stopped == Some(StopReason::Monitor);
    out.wrong_ipoc = ctrl.wrong_ipoc;
    out.wrong_type = ctrl.wrong_type;
    out.malformed = ctrl.malformed;
    out.poscorr_clamped = ctrl.poscorr_clamped;
    out.axiscorr_clamped = ctrl.axiscorr_clamped;
    out.wrong_kind = ctrl.wrong_kind;
    out.akorr_range_deg = ctrl.akorr_range_deg;
    out.stopped = ctrl.stopped;
    out.peak_speed_share = ctrl.peak_speed_share;
    out.peak_acceleration_share = ctrl.peak_acceleration_share;
    out.rates_over = ctrl.rates_over;
    Ok(out)
}
