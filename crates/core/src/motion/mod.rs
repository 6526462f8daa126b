//! Motion: from the current [`StrikePlan`](crate::plan::StrikePlan) to one
//! TCP setpoint per RSI cycle in the robot's BASE frame B, and the PC-side
//! safety that every setpoint passes before it is sent.
//!
//! - `limits`: the cell's limits (workspace box, velocity, acceleration,
//!   jerk) in the generator's units, and the T→B conversion of a plan.
//! - `generator`: the stroke — reach the hitting pose at the hitting time
//!   with the bat velocity, follow through, return home — generated online
//!   with Ruckig (jerk-limited, continuous in velocity and acceleration) and
//!   re-planned whenever a refined plan arrives; a refinement the
//!   committed axes can no longer meet by re-planning is blended in
//!   (`blend`: a quintic correction on top of the stroke).
//! - `reach`: what the arm can do at a hitting point — the face tilts
//!   it can present there and the fastest bat its axes deliver — for the
//!   aim, and the joint checks the generator applies to every stroke.
//! - `safety`: the last line: workspace box, per-cycle step (velocity) and
//!   step-change (acceleration) limits, with braking before the box walls.
//!   Whatever the generator or a hostile plan asks, nothing outside these
//!   limits leaves this module.
//!
//! A pose here is `[x, y, z, a, b, c]`: metres and radians in B, KUKA's
//! A/B/C = rotations about Z/Y/X, angles unwrapped (continuous, near home).
//! This module never reads a clock and never allocates per cycle.

mod blend;
pub(crate) mod generator;
pub(crate) mod homing;
pub(crate) mod limits;
pub(crate) mod margins;
pub(crate) mod reach;
pub(crate) mod safety;

pub use generator::{Phase, PlanRejected, StrokeGenerator, StrokeTarget};
pub use homing::{HomingLimits, HomingPath, WayHomeBlocked};
pub use limits::MotionLimits;
pub use reach::ReachMap;
pub use safety::SafetyFilter;
