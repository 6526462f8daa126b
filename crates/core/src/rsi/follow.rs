//! Does the arm follow what the session commands? The servo model of
//! `calib/robot.toml [servo]` predicts the axes from the joints of the
//! corrections sent: a correction answered in cycle k reaches the drives
//! after the dead time, and each axis closes α = 1 − e^(−T/τ) of its gap
//! per cycle; the actual pose of that cycle comes with the next request.
//! Where `RIst` stays beyond the tolerance from the predicted axes' TCP for
//! a few cycles in a row, the arm stopped following: brakes applied, an
//! operator stop, a KSS error, the controller's load check (`[start]
//! follow_*`). Fixed size, no allocation; one forward kinematics a cycle.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use heapless::Deque;

use crate::kinematics::{AXES, Arm, Joints, Pose};

/// The longest dead time the monitor models, cycles.
pub(crate) const MAX_DEAD_CYCLES: usize = 31;

/// How far the arm strays from the model (see the module doc).
#[derive(Clone, Debug)]
pub struct FollowMonitor {
    alpha: f64,
    dead: usize,
    tol_m: f64,
    tol_rad: f64,
    cycles: u32,
    /// Joints sent, oldest first: `dead + 1` of them once primed.
    line: Deque<Joints, { MAX_DEAD_CYCLES + 1 }>,
    predicted: Joints,
    /// The TCP of `predicted` (an arm at rest: no kinematics a cycle).
    tcp: Option<(Joints, Pose)>,
    over: u32,
    /// The last error seen: position (m) and turn (rad).
    pub error: (f64, f64),
    /// The largest position error seen while following, m.
    pub max_error_m: f64,
}

impl FollowMonitor {
    /// A monitor for a lag step `alpha`, `dead` cycles of dead time (beyond
    /// the answer's own cycle), and the tolerance (m, rad) that `cycles`
    /// cycles in a row must exceed.
    pub fn new(alpha: f64, dead: usize, tol_m: f64, tol_rad: f64, cycles: u32) -> Self {
        FollowMonitor {
            alpha: alpha.clamp(0.0, 1.0),
            dead: dead.min(MAX_DEAD_CYCLES),
            tol_m,
            tol_rad,
            cycles: cycles.max(1),
            line: Deque::new(),
            predicted: Joints([0.0; AXES]),
            tcp: None,
            over: 0,
            error: (0.0, 0.0),
            max_error_m: 0.0,
        }
    }

    /// The arm at rest at joints `q`, commanded there, before the first
    /// request's answer ([`Self::commanded`] follows, with no observation).
    pub fn reset(&mut self, q: Joints) {
        self.line.clear();
        for _ in 0..self.dead {
            let _ = self.line.push_back(q); // dead < capacity
        }
        self.predicted = q;
        self.over = 0;
    }

    /// The axes are at `q`, whatever was predicted (after missed cycles,
    /// or a stop): the model restarts from them, the commands kept.
    pub fn resync(&mut self, q: Joints) {
        self.predicted = q;
        self.over = 0;
    }

    /// The joints predicted for the last request.
    pub fn predicted(&self) -> Joints {
        self.predicted
    }

    /// The joints of the correction answered this cycle (after
    /// [`Self::observe`]).
    /// Cycles with no observation (held, stopped) keep the line as long.
    pub fn commanded(&mut self, q: &Joints) {
        while self.line.len() > self.dead {
            self.line.pop_front();
        }
        let _ = self.line.push_back(*q);
    }

    /// This request's `RIst` against the model's axes under `arm`. Returns
    /// true once it has been beyond `scale` times the tolerance `cycles`
    /// times in a row.
    pub fn observe(&mut self, rist: &Pose, arm: &Arm, scale: f64) -> bool {
        if !(rist.position.iter().all(|x| x.is_finite()) && rist.rotation.matrix().iter().all(|x| x.is_finite())) {
            return false;
        }
        if self.line.len() > self.dead {
            let cmd = self.line.pop_front().unwrap_or(self.predicted);
            for i in 0..AXES {
                self.predicted.0[i] += self.alpha * (cmd.0[i] - self.predicted.0[i]);
            }
        }
        let tcp = match self.tcp {
            Some((q, p)) if q == self.predicted => p,
            _ => {
                let p = arm.tcp(&self.predicted);
                self.tcp = Some((self.predicted, p));
                p
            }
        };
        let (dp, da) = rist.distance(&tcp);
        self.error = (dp, da);
        if dp > self.tol_m * scale || da > self.tol_rad * scale {
            self.over += 1;
        } else {
            self.over = 0;
            self.max_error_m = self.max_error_m.max(dp);
        }
        self.over >= self.cycles
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lagging_arm_follows_and_a_braked_one_does_not() {
        let robot = crate::calib::Calibration::default_cell().robot;
        let arm = robot.arm();
        let home = robot.home_joints(&arm).unwrap();
        let (alpha, dead) = (0.2, 3);
        let mut m = FollowMonitor::new(alpha, dead, 0.010, 0.05, 3);
        m.reset(home);
        // The arm as the mock KR C4 runs it: A1 turns at 60°/s; the drives
        // take the command from `dead` cycles before.
        let mut line = std::collections::VecDeque::from(vec![home; dead]);
        let mut actual = home;
        let cmd = |k: usize| {
            let mut q = home;
            q.0[0] += (60f64 * 0.004 * k as f64).to_radians();
            q
        };
        for k in 0..100 {
            assert!(!m.observe(&arm.tcp(&actual), &arm, 1.0), "cycle {k}");
            m.commanded(&cmd(k));
            let target = line.pop_front().unwrap();
            line.push_back(cmd(k));
            actual.0[0] += alpha * (target.0[0] - actual.0[0]);
        }
        assert!(m.max_error_m < 1e-9, "exact for the model: {}", m.max_error_m);
        // Brakes: the arm stands; the error passes 10 mm, then three cycles.
        let mut fired = None;
        for k in 0..20 {
            if m.observe(&arm.tcp(&actual), &arm, 1.0) {
                fired = Some(k);
                break;
            }
            m.commanded(&cmd(100 + k));
        }
        let k = fired.expect("noticed");
        assert!((3..12).contains(&k), "after {k} cycles");
        // Non-finite RIst is not evidence either way.
        let mut nan = arm.tcp(&actual);
        nan.position.x = f64::NAN;
        assert!(!m.observe(&nan, &arm, 1.0));
    }
}
