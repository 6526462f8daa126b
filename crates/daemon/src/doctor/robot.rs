//! `robot_start` (only with `topspin doctor --robot-wait S`): listens on
//! `network.rsi_bind` for the controller's RSI requests, answering each
//! with a zero correction as `calibrate cell --rsi` does (nothing moves),
//! and says what `topspin run` would do with the arm where it stands
//! ([`topspin_core::rsi::assess`]):
//! - pass: the arm is home, `RIst` the kinematics of `AIPos` under the
//!   calibration's tool and base;
//! - warn: off home, the way home at the commissioning speed is clear (the
//!   daemon takes it first); no request came (RSI not on);
//! - fail: another TOOL_DATA or BASE_DATA, an unusable pose, or a way home
//!   that is unsafe (the daemon would hold).

use topspin_core::calib::Calibration;
use topspin_core::motion::MotionLimits;
use topspin_core::rsi::SessionConfig;
use topspin_core::rsi::{StartRefused, Verdict, assess};

use super::Check;
use crate::config::DaemonConfig;
use crate::touch::{TouchError, TouchListener};

/// The check's name.
pub const NAME: &str = "robot_start";

/// Waits up to `wait_s` for one request on the configured RSI address.
pub fn check(cfg: &DaemonConfig, cal: &Calibration, wait_s: f64) -> Check {
    let bind = cfg.network.rsi_bind;
    let mut listener = match TouchListener::bind(bind, &cfg.rsi.sentype) {
        Ok(l) => l,
        Err(e) => {
            return Check::warn(
                NAME,
                format!("could not listen on {bind}: {e}"),
                "stop `topspin run` (it holds the RSI port) and run doctor again",
            );
        }
    };
    let request = listener.take_requests(1, std::time::Duration::from_secs_f64(wait_s));
    match request {
        Ok(r) => judge(cal, r.first().map(|(p, _)| *p), r.first().and_then(|(_, a)| *a)),
        Err(TouchError::NoRist) => judge(cal, None, None),
        Err(e) => {
            Check::warn(NAME, format!("{e}"), "start RSI on the controller (topspin_rsi.src) and run doctor again")
        }
    }
}

/// The verdict on one request's `RIst` and `AIPos`.
pub fn judge(
    cal: &Calibration,
    rist: Option<topspin_core::rsi::KukaPose>,
    aipos: Option<topspin_core::rsi::Axes>,
) -> Check {
    let s = SessionConfig::from_calibration(cal, "ImFree");
    let lim = MotionLimits::from_robot(&cal.robot);
    let start = assess(&lim, &s.start, &s.homing, rist, aipos, None, 0.0);
    let at = format!("the arm stands {:.0} mm and {:.1}° from home", start.from_mm, start.from_deg);
    match start.verdict {
        Verdict::Home => Check::pass(NAME, format!("{at}: the daemon plays at once")),
        Verdict::GoHome(path) => Check::warn(
            NAME,
            format!("{at}: the daemon will take it home at the commissioning speed first ({:.1} s)", path.duration()),
            "or PTP to home in topspin_rsi.src before RSI_ON",
        ),
        Verdict::Refused(r @ StartRefused::Frames(_)) => Check::fail(NAME, format!("{r}"), r.fix()),
        Verdict::Refused(r) => Check::fail(NAME, format!("{at}: the daemon would hold: {r}"), r.fix()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::doctor::Status;
    use topspin_core::rsi::KukaPose;

    #[test]
    fn the_start_is_judged_as_the_daemon_would() {
        let cal = Calibration::default_cell();
        let arm = cal.robot.arm();
        let home = cal.robot.home_joints(&arm).unwrap();
        let kuka = |q: &topspin_core::kinematics::Joints| KukaPose::from_pose(&arm.tcp(q));
        assert_eq!(judge(&cal, Some(kuka(&home)), Some(home.degrees())).status, Status::Pass);
        let mut q = home;
        q.0[0] += 0.3;
        let c = judge(&cal, Some(kuka(&q)), Some(q.degrees()));
        assert_eq!(c.status, Status::Warn, "{c:?}");
        assert!(c.detail.contains("commissioning speed"), "{c:?}");
        // RIst 30 mm off the kinematics of AIPos: another tool.
        let mut p = kuka(&home);
        p.z -= 30.0;
        let c = judge(&cal, Some(p), Some(home.degrees()));
        assert_eq!(c.status, Status::Fail, "{c:?}");
        assert!(c.detail.contains("TOOL_DATA") && c.fix.as_deref().unwrap().contains("TOOL_DATA"), "{c:?}");
        let c = judge(&cal, None, None);
        assert_eq!(c.status, Status::Fail);
        assert!(c.fix.as_deref().unwrap().contains("PTP to home"), "{c:?}");
    }
}
