//! What the RSI session finds at the first request of a run: whether the
//! arm's pose can be used at all, whether `RIst` is the forward kinematics
//! of `AIPos` under the calibration's tool and base, and so whether the
//! session may play where the arm stands, must go home first
//! (`motion::homing`), or must hold.
//!
//! [`check_frames`] owns the tool/base check (also used by `identify` and
//! `calibrate cell`): a KRL program that runs another TOOL_DATA or
//! BASE_DATA than `calib/robot.toml` reports `RIst` in other frames, and
//! every correction would land the bat elsewhere than planned. One pose
//! cannot tell the two apart for certain; the report gives both readings
//! (the TOOL_DATA, or the BASE offset, that would explain the pose) and
//! names the more likely: the one a person would have typed, with fewer
//! non-zero values (a tool length wrong, the flange as the tool, a base
//! turned about its z axis).

use crate::calib::robot::StartPolicy;
use crate::geometry::{Pose6, unwrap_near};
use crate::kinematics::{Arm, Joints, LimitViolation, Pose};
use crate::motion::MotionLimits;
use crate::motion::homing::{HomingLimits, HomingPath, WayHomeBlocked};
use crate::rsi::codec::{Axes, CodecError, KukaPose};

/// Which frame most likely differs from the calibration.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum LikelyFrame {
    /// `$TOOL` (TOOL_DATA) differs from `[robot]` tool_length_m / tool_abc_deg.
    Tool,
    /// `$BASE` (BASE_DATA) is not the robot's foot.
    Base,
}

impl LikelyFrame {
    /// KRL's name for it.
    pub fn krl(self) -> &'static str {
        match self {
            LikelyFrame::Tool => "TOOL_DATA",
            LikelyFrame::Base => "BASE_DATA",
        }
    }
}

/// `RIst` is not the forward kinematics of `AIPos` (see the module doc).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FramesMismatch {
    /// Distance between `RIst` and the TCP of `AIPos`, mm.
    pub mm: f64,
    /// Angle between their orientations, degrees.
    pub deg: f64,
    /// The more likely cause.
    pub likely: LikelyFrame,
    /// The TOOL_DATA (X, Y, Z mm, A, B, C degrees, in the flange frame)
    /// under which `AIPos` gives `RIst`.
    pub tool: [f64; 6],
    /// The frame (X, Y, Z mm, A, B, C degrees, in our BASE) in which
    /// `RIst` is the TCP of `AIPos`: BASE_DATA relative to the robot's foot.
    pub base: [f64; 6],
}

impl core::fmt::Display for FramesMismatch {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let six = |v: &[f64; 6]| {
            // (+ 0.0: no "-0.0" for a value that rounds to zero)
            let r = v.map(|x| (x * 10.0).round() / 10.0 + 0.0);
            format!("{{X {:.1}, Y {:.1}, Z {:.1}, A {:.1}, B {:.1}, C {:.1}}}", r[0], r[1], r[2], r[3], r[4], r[5])
        };
        write!(
            f,
            "RIst is {:.1} mm and {:.1}° from the forward kinematics of AIPos: most likely {} (the pose fits \
             TOOL_DATA {} or a BASE_DATA of {}); make the KRL program's TOOL_DATA and BASE_DATA those of \
             calib/robot.toml, or calibrate them",
            self.mm,
            self.deg,
            self.likely.krl(),
            six(&self.tool),
            six(&self.base)
        )
    }
}

/// Why a start cannot be used as it is.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum StartRefused {
    /// No `RIst` or no `AIPos` in the request (the SEND list must carry
    /// both: without the joints the tool and base cannot be checked).
    #[error("the first request has no {0} (add DEF_{0} to the SEND list of the Ethernet configuration)")]
    Missing(&'static str),
    /// `RIst` or `AIPos` has a non-finite or missing value.
    #[error("the first request's {0} has a value that is missing or not finite")]
    Unreadable(&'static str),
    /// `AIPos` outside the software limits.
    #[error("the first request's AIPos breaks {0}")]
    JointLimit(LimitViolation),
    /// `RIst` is not the forward kinematics of `AIPos`.
    #[error("{0}")]
    Frames(FramesMismatch),
    /// The way home is unsafe.
    #[error("{0}")]
    WayHome(WayHomeBlocked),
}

impl StartRefused {
    /// A short key for counting refusals.
    pub fn key(&self) -> &'static str {
        match self {
            StartRefused::Missing(_) => "missing",
            StartRefused::Unreadable(_) => "unreadable",
            StartRefused::JointLimit(_) => "joint_limit",
            StartRefused::Frames(_) => "tool_or_base",
            StartRefused::WayHome(_) => "way_home",
        }
    }

    /// What to do about it, for the log line.
    pub fn fix(&self) -> &'static str {
        match self {
            StartRefused::Frames(_) => "fix TOOL_DATA/BASE_DATA, then restart RSI",
            _ => "PTP to home in topspin_rsi.src, then restart RSI",
        }
    }
}

/// `RIst` and `AIPos` as the session's units (m, rad), checked for use;
/// `bad` is the request's unreadable element, if any
/// ([`RobFrame::parse_lenient`](super::codec::RobFrame::parse_lenient)).
pub fn read_start(
    arm: &Arm,
    rist: Option<KukaPose>,
    aipos: Option<Axes>,
    bad: Option<CodecError>,
) -> Result<(Pose, Joints), StartRefused> {
    let unreadable = |name: &'static str| matches!(bad, Some(CodecError::BadNumber { element } | CodecError::MissingAttribute { element, .. }) if element == name);
    if unreadable("RIst") {
        return Err(StartRefused::Unreadable("RIst"));
    }
    if unreadable("AIPos") {
        return Err(StartRefused::Unreadable("AIPos"));
    }
    let rist = rist.ok_or(StartRefused::Missing("RIst"))?;
    if !rist.to_array().iter().all(|x| x.is_finite()) {
        return Err(StartRefused::Unreadable("RIst"));
    }
    let pose = rist.to_pose();
    let q = match aipos {
        None => return Err(StartRefused::Missing("AIPos")),
        Some(a) if !a.iter().all(|x| x.is_finite()) => return Err(StartRefused::Unreadable("AIPos")),
        Some(a) => {
            let q = Joints::from_degrees(a);
            // Position limits only (checked first): the singular wrist is
            // the way home's matter.
            match arm.limits.check_position(&q) {
                Err(v) if v.kind != crate::kinematics::LimitKind::SingularWrist => {
                    return Err(StartRefused::JointLimit(v));
                }
                _ => q,
            }
        }
    };
    Ok((pose, q))
}

/// KUKA's X, Y, Z (mm), A, B, C (degrees) of a frame.
fn kuka(p: &Pose) -> [f64; 6] {
    KukaPose::from_pose(p).to_array()
}

/// Values a person would have typed differently: positions over half a
/// millimetre, angles over a tenth of a degree.
fn typed(v: &[f64; 6]) -> usize {
    v[..3].iter().filter(|x| x.abs() > 0.5).count() + v[3..].iter().filter(|x| x.abs() > 0.1).count()
}

/// `RIst` (`rist`) against the TCP of `AIPos` (`q`) under `arm`'s tool:
/// `None` within `tol_mm` and `tol_deg`, else the mismatch.
pub fn check_frames(arm: &Arm, rist: &Pose, q: &Joints, tol_mm: f64, tol_deg: f64) -> Option<FramesMismatch> {
    let fk = arm.forward(q);
    let (d, th) = rist.distance(&fk.tcp);
    let (mm, deg) = (d * 1e3, th.to_degrees());
    if mm < tol_mm && deg < tol_deg {
        return None;
    }
    // Tool reading: RIst = flange · tool'. Base reading: RIst = E · tcp.
    let tool = fk.flange.inverse().compose(rist);
    let base = rist.compose(&fk.tcp.inverse());
    let ours = arm.geometry.tool;
    let tool_change = kuka(&ours.inverse().compose(&tool));
    let base_k = kuka(&base);
    // Fewer values to type wins; a tie goes to the tool, the frame a KRL
    // program selects with every motion.
    let likely = if typed(&base_k) < typed(&tool_change) { LikelyFrame::Base } else { LikelyFrame::Tool };
    Some(FramesMismatch { mm, deg, likely, tool: kuka(&tool), base: base_k })
}

/// What a start allows.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Verdict {
    /// Home within the tolerance: play.
    Home,
    /// Off home: this way home first, at the commissioning speed.
    GoHome(HomingPath),
    /// Hold where the arm stands, with zero corrections.
    Refused(StartRefused),
}

/// The arm at the first request of a run, and what it allows.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Start {
    /// `RIst` in B (m, rad; angles within π of home), or home where it is
    /// unusable.
    pub pose: Pose6,
    /// `AIPos`, or the solution for `pose` nearest the home joints.
    pub joints: Joints,
    /// How far `pose` is from home, mm …
    pub from_mm: f64,
    /// … and degrees.
    pub from_deg: f64,
    /// What the session does.
    pub verdict: Verdict,
}

/// How far `pose` (B, m and rad) is from the cell's home: mm and degrees.
pub(crate) fn from_home(lim: &MotionLimits, pose: &Pose6) -> (f64, f64) {
    let (d, a) = Pose::from_pose6(pose).distance(&Pose::from_pose6(&lim.home));
    (d * 1e3, a.to_degrees())
}

/// The first request's `RIst`, `AIPos` (and unreadable element `bad`)
/// against the cell: usable, the calibration's tool and base, home or the
/// way home from there (starting at `t0` s). The RSI session's decision,
/// and `topspin doctor`'s.
pub fn assess(
    lim: &MotionLimits,
    policy: &StartPolicy,
    homing: &HomingLimits,
    rist: Option<KukaPose>,
    aipos: Option<Axes>,
    bad: Option<CodecError>,
    t0: f64,
) -> Start {
    let home = lim.home;
    let read = read_start(&lim.arm, rist, aipos, bad);
    let pose = match &read {
        Ok((p, _)) => {
            let mut s = p.to_pose6();
            for i in 3..6 {
                s[i] = unwrap_near(s[i], home[i]);
            }
            s
        }
        Err(_) => home,
    };
    let joints = match &read {
        Ok((_, q)) => *q,
        Err(_) => lim.arm.inverse_near(&Pose::from_pose6(&pose), &lim.home_joints).unwrap_or(lim.home_joints),
    };
    let (from_mm, from_deg) = from_home(lim, &pose);
    let verdict = match read {
        Err(r) => Verdict::Refused(r),
        Ok((p, q))
            if let Some(m) =
                check_frames(&lim.arm, &p, &q, policy.frames_tolerance_mm, policy.frames_tolerance_deg) =>
        {
            Verdict::Refused(StartRefused::Frames(m))
        }
        Ok(_) if policy.is_home(from_mm, from_deg) => Verdict::Home,
        Ok(_) => match HomingPath::plan(&lim.arm, homing, &pose, &joints, &lim.home_joints, t0) {
            Ok(path) => Verdict::GoHome(path),
            Err(e) => Verdict::Refused(StartRefused::WayHome(e)),
        },
    };
    Start { pose, joints, from_mm, from_deg, verdict }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;

    fn arm() -> (Arm, Joints) {
        let r = Calibration::default_cell().robot;
        let arm = r.arm();
        let q = r.home_joints(&arm).unwrap();
        (arm, q)
    }

    #[test]
    fn the_calibrations_own_frames_pass() {
        let (arm, q) = arm();
        let tcp = arm.tcp(&q);
        assert_eq!(check_frames(&arm, &tcp, &q, 5.0, 1.0), None);
        let mut q2 = q;
        q2.0[0] += 0.3;
        q2.0[4] -= 0.2;
        assert_eq!(check_frames(&arm, &arm.tcp(&q2), &q2, 5.0, 1.0), None);
    }

    #[test]
    fn a_wrong_tool_length_is_named_as_the_tool() {
        let (arm, q) = arm();
        // The KRL program's tool is 30 mm longer along the flange's z.
        let mut other = arm;
        other.geometry.tool = arm.geometry.tool.compose(&Pose::from_xyz_abc([0.0, 0.0, 0.0], [0.0; 3]));
        other.geometry.tool.position.z += 0.03;
        let mut q2 = q;
        q2.0[3] += 0.4; // a pose where the flange is not straight down
        q2.0[4] -= 0.3;
        let m = check_frames(&arm, &other.tcp(&q2), &q2, 5.0, 1.0).expect("30 mm off");
        assert!((m.mm - 30.0).abs() < 1e-6 && m.deg < 1e-6, "{m:?}");
        assert_eq!(m.likely, LikelyFrame::Tool);
        assert!((m.tool[2] - (arm.geometry.tool.position.z + 0.03) * 1e3).abs() < 1e-6, "{:?}", m.tool);
        // The flange itself as the TCP ($TOOL = $NULLFRAME).
        let flange = arm.forward(&q2).flange;
        let m = check_frames(&arm, &flange, &q2, 5.0, 1.0).unwrap();
        assert_eq!(m.likely, LikelyFrame::Tool);
        assert!(m.tool.iter().all(|x| x.abs() < 1e-6), "{:?}", m.tool);
        assert!(m.to_string().contains("most likely TOOL_DATA"), "{m}");
    }

    #[test]
    fn a_base_turned_about_its_z_axis_is_named_as_the_base() {
        let (arm, q) = arm();
        let mut q2 = q;
        q2.0[3] += 0.4;
        q2.0[4] -= 0.3;
        let turned = Pose::from_xyz_abc([0.0; 3], [3f64.to_radians(), 0.0, 0.0]);
        let rist = turned.compose(&arm.tcp(&q2));
        let m = check_frames(&arm, &rist, &q2, 5.0, 1.0).expect("3° off");
        assert!((m.deg - 3.0).abs() < 1e-6, "{m:?}");
        assert_eq!(m.likely, LikelyFrame::Base);
        assert!((m.base[3] - 3.0).abs() < 1e-6 && m.base[..3].iter().all(|x| x.abs() < 1e-6), "{:?}", m.base);
    }

    #[test]
    fn unusable_start_poses_are_named() {
        let (arm, q) = arm();
        let rist = Some(KukaPose::from_array([350.0, 0.0, 450.0, 180.0, 0.0, 0.0]));
        assert_eq!(read_start(&arm, None, None, None), Err(StartRefused::Missing("RIst")));
        assert_eq!(read_start(&arm, rist, None, None), Err(StartRefused::Missing("AIPos")));
        let nan = Some(KukaPose::from_array([f64::NAN, 0.0, 450.0, 180.0, 0.0, 0.0]));
        assert_eq!(read_start(&arm, nan, None, None), Err(StartRefused::Unreadable("RIst")));
        let bad = Some(CodecError::BadNumber { element: "RIst" });
        assert_eq!(read_start(&arm, None, None, bad), Err(StartRefused::Unreadable("RIst")));
        let mut a = q.degrees();
        a[2] = f64::INFINITY;
        assert_eq!(read_start(&arm, rist, Some(a), None), Err(StartRefused::Unreadable("AIPos")));
        let mut a = q.degrees();
        a[0] = 171.0;
        let Err(StartRefused::JointLimit(v)) = read_start(&arm, rist, Some(a), None) else { panic!("A1 at 171°") };
        assert_eq!(v.axis, crate::kinematics::Axis::A1);
        let (p, j) = read_start(&arm, rist, Some(q.degrees()), None).unwrap();
        assert!((p.position.x - 0.35).abs() < 1e-12 && j.max_abs_diff(&q) < 1e-12);
    }
}
