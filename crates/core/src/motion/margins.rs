//! The stroke's margins: how much of each axis's limits a stroke may use
//! and how far inside the software limits, the workspace and the
//! singularities it keeps. They are the generator's policy
//! ([`super::generator`] applies them to every stroke) and the reach map's
//! premise ([`super::reach`] maps what the arm can do within them), so
//! they live apart from both.

/// Share of each axis's speed and acceleration a stroke may use (the rest
/// absorbs the lag's feed-forward and the refinements to come).
pub(crate) const JOINT_LIMIT_FRACTION: f64 = 0.97;

/// Time for an axis to reach full acceleration (sets the jerk limit), s.
pub(crate) const JERK_RAMP_S: f64 = 0.0125;

/// A stroke's targets keep this far inside the software limits, rad (the
/// path between may overshoot its ends a little, and the lag's
/// feed-forward leads it).
pub(crate) const LIMIT_MARGIN_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// A stroke at the full limits keeps this far inside the software limits
/// all along its path, rad: Ruckig's fastest profile may swing an axis
/// well past its target (by 10° and more) to turn it round. At the swing's
/// extreme the axis is at rest, so the lag's feed-forward adds little
/// there; the margin covers the instants between the generator's path
/// checks (under half a degree at full acceleration over half a second).
/// A wider margin refuses strokes the arm can play.
pub(crate) const PATH_LIMIT_MARGIN_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;

/// How far inside the workspace box a stroke's path keeps the TCP at the
/// generator's path checks, and its follow-through's rest point, m:
/// between two checks the TCP moves on by up to ~0.6 mm where it turns (a
/// run-up's far end), braking passes its rest point by about as much, and
/// the setpoints the safety filter sees lead the path (the lag's
/// feed-forward). At 2 mm an
/// open face's run-up, which comes up from below along the face's normal,
/// met the filter at the box's floor (under 1 mm, a braked TCP and axis
/// steps the controller counted) in two virtual-cell sessions of 425.
pub(crate) const PATH_WALL_MARGIN_M: f64 = 0.005;

/// How far inside the workspace's orientation range a stroke's path keeps
/// the bat at the generator's path checks, rad: the safety filter brakes
/// an angle that nears its bound at speed, and between two checks the
/// blade turns on by up to a degree (a path that touched 45.0° of roll
/// was braked there).
pub(crate) const PATH_ORIENTATION_MARGIN_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;

/// A stroke's face keeps this far inside the workspace's orientation
/// range (`workspace.abc_range_deg`), rad: the joint-space path into and
/// out of the hitting pose turns the bat on past it, and the safety filter
/// brakes a stroke that would leave the range (a step the axes feel).
pub(crate) const ORIENTATION_MARGIN_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// A stroke's targets keep A3 this far from the stretched elbow, rad.
pub(crate) const ELBOW_MARGIN_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// A stroke's joints keep |A5| at least this many times the singular
/// threshold, on the same side as now.
pub(crate) const WRIST_MARGIN: f64 = 5.0;

/// A stroke at the full limits keeps |A5| at least this many times the
/// singular threshold all along its path, on the side it is on now:
/// Ruckig's fastest profile swings A5 past its target as it does every
/// axis, towards the singular wrist where the target is low and the face
/// open (the controller stops there). At the swing's extreme A5 is at
/// rest; between two path checks it moves under a degree.
pub(crate) const PATH_WRIST_MARGIN: f64 = 2.0;

/// Step used to turn a bat velocity into joint velocities, s.
pub(crate) const VELOCITY_STEP_S: f64 = 1e-3;
