//! Worlds whose physics is not the estimator's: the lift linear
//! at the two scales the codes in use disagree on, saturating, and with a
//! lift-crisis valley; drag, restitution and friction across the
//! literature's ranges; spin axes that are not perpendicular to the flight;
//! and every ball its own (drag and lift vary from ball to ball). The fit
//! is judged here on flights it was not written for.
//!
//! The worlds are fixed points drawn once from the ranges of DESIGN §3 and
//! the issue (C_D 0.40–0.55, e 0.85–0.95, μ 0.15–0.35) before any fit was
//! tuned on them; each pairs a lift with a different table and air, so no
//! single constant is right twice.
//!
//! Two of them fly the lift real balls showed, as measured and without a
//! law ([`LiftModel::Measured`], docs/physics.md): `real-launcher` the
//! model-free C_L of 166 launcher flights with spin read from dotted
//! balls, `real-rally` the C_L that brings 610 elite human strokes to the
//! table at their recorded bounce time. Both saturate above S ≈ 0.5, so a
//! flight cannot tell a fast spin from a medium one; each ball has its own
//! C_D in 0.40–0.55 and lift scale ×0.75–1.30. These are the worlds the
//! goals are judged in; the laws above stay as stress tests.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use topspin_core::calib::Calibration;
use topspin_core::physics::{FlightScales, LiftModel, LiftPoints, PhysicsParams, Propagator};

use crate::launcher::{SpinAxis, launch_with};
use crate::tracker::{TrackerModel, observe};
use crate::truth::Truth;
use crate::{Setting, SimBall, ball_rngs};

/// One simulated world: its physics, how much its balls differ, and how
/// its launcher spins them.
#[derive(Clone, Debug, PartialEq)]
pub struct World {
    /// Short name (a table row).
    pub name: &'static str,
    /// What is unlike the estimator, in a few words.
    pub about: &'static str,
    /// Ball, air and table of this world (mass, radius, gravity and air
    /// density are the calibration's).
    pub physics: PhysicsParams,
    /// Each ball's drag multiplier is drawn uniformly from this range.
    pub ball_drag: (f64, f64),
    /// Each ball's lift multiplier is drawn uniformly from this range.
    pub ball_lift: (f64, f64),
    /// The launcher's spin axes.
    pub axis: SpinAxis,
}

impl World {
    /// This world's balls from a wheel launcher: spin axes perpendicular
    /// to the exit velocity (the cell's launcher, and the goals' setting).
    pub fn with_launcher_axes(self) -> World {
        World { axis: SpinAxis::Perpendicular, ..self }
    }
}

/// Ball-to-ball variation of the drag (seam, surface, a dented ball).
const BALL_DRAG: (f64, f64) = (0.95, 1.10);
/// Ball-to-ball variation of the lift.
const BALL_LIFT: (f64, f64) = (0.85, 1.15);
/// Spin axes tipped towards the flight by up to this, degrees.
const SKEW_DEG: f64 = 20.0;

/// C_L of 166 launcher flights with dotted balls, read model-free from
/// each flight's curvature: 0.19, 0.24, 0.25, 0.31 over S 0.1–0.3,
/// 0.3–0.5, 0.5–1.0 and 1–3, placed at each bin's middle.
pub const REAL_LAUNCHER_LIFT: ([f64; 4], [f64; 4]) = ([0.2, 0.4, 0.75, 2.0], [0.19, 0.24, 0.25, 0.31]);
/// C_L that brings 610 elite human strokes to the table at their recorded
/// bounce: 0.10 below S 0.3, 0.14 at 0.3–0.5, 0.175 at 0.5–0.9, 0.215 above.
pub const REAL_RALLY_LIFT: ([f64; 4], [f64; 4]) = ([0.15, 0.4, 0.7, 1.2], [0.10, 0.14, 0.175, 0.215]);
/// Each ball's own C_D of the measured worlds: 0.40–0.55 about their 0.475.
const REAL_BALL_DRAG: (f64, f64) = (0.40 / 0.475, 0.55 / 0.475);
/// Each ball's own lift scale of the measured worlds.
const REAL_BALL_LIFT: (f64, f64) = (0.75, 1.30);

/// A measured lift curve as a [`LiftModel`].
pub fn measured_lift((s, c_l): ([f64; 4], [f64; 4])) -> LiftModel {
    let pts = |v: &[f64]| LiftPoints::new(v).expect("four points");
    LiftModel::Measured { s: pts(&s), c_l: pts(&c_l) }
}

/// The eight worlds of `topspin eval worlds`, on the cell of `cal`.
pub fn worlds(cal: &Calibration) -> Vec<World> {
    let base = &cal.physics;
    let world = |name, about, lift, c_d, e, mu| World {
        name,
        about,
        physics: PhysicsParams { lift, drag_coefficient: c_d, restitution: e, friction: mu, ..base.clone() },
        ball_drag: BALL_DRAG,
        ball_lift: BALL_LIFT,
        axis: SpinAxis::Skewed { max_deg: SKEW_DEG },
    };
    let sawicki = LiftModel::Saturating { c_m: 1.0, s_half: 0.5 };
    // A lift measured on real balls, each ball with its own drag and lift.
    let measured = |name, about, curve, e, mu| World {
        ball_drag: REAL_BALL_DRAG,
        ball_lift: REAL_BALL_LIFT,
        ..world(name, about, measured_lift(curve), 0.475, e, mu)
    };
    vec![
        world(
            "linear-weak",
            "C_L = 0.32·S (tt3d's scale), C_D 0.50, e 0.88, μ 0.30",
            LiftModel::Constant { c_m: 0.32 },
            0.50,
            0.88,
            0.30,
        ),
        world(
            "linear-strong",
            "C_L = 1.47·S (MPI ball_prediction's scale), C_D 0.42, e 0.93, μ 0.18",
            LiftModel::Constant { c_m: 1.47 },
            0.42,
            0.93,
            0.18,
        ),
        world("saturating", "C_L = S/(1 + 2S) (Sawicki), C_D 0.55, e 0.85, μ 0.35", sawicki, 0.55, 0.85, 0.35),
        world(
            "crisis",
            "C_L saturating with an 80 % valley at S 0.5 (lift crisis), C_D 0.40, e 0.95, μ 0.15",
            LiftModel::Crisis { c_m: 1.0, s_half: 0.5, s_valley: 0.5, depth: 0.8, width: 0.15 },
            0.40,
            0.95,
            0.15,
        ),
        world(
            "heavy-air",
            "saturating lift, 1.5 × the calibrated C_D, e 0.90, μ 0.25",
            sawicki,
            1.5 * base.drag_coefficient,
            0.90,
            0.25,
        ),
        World {
            ball_drag: (1.05, 1.25),
            ..world(
                "other-table",
                "saturating lift, the calibrated C_D with every ball's drag ×1.05–1.25, e 0.92, μ 0.20",
                sawicki,
                base.drag_coefficient,
                0.92,
                0.20,
            )
        },
        measured(
            "real-launcher",
            "C_L measured on 166 launcher flights (saturates above S 0.5), each ball's C_D 0.40–0.55 and lift \
             ×0.75–1.30, e 0.92, μ 0.20",
            REAL_LAUNCHER_LIFT,
            0.92,
            0.20,
        ),
        measured(
            "real-rally",
            "C_L of 610 elite strokes' bounce times (saturates above S 0.5), each ball's C_D 0.40–0.55 and lift \
             ×0.75–1.30, e 0.90, μ 0.25",
            REAL_RALLY_LIFT,
            0.90,
            0.25,
        ),
    ]
}

/// The world named `name`, if there is one.
pub fn world_named(cal: &Calibration, name: &str) -> Option<World> {
    worlds(cal).into_iter().find(|w| w.name == name)
}

/// Ball `k`'s own drag and lift multipliers in a world (a stream of its own).
fn ball_scales(world: &World, seed: u64, k: usize) -> FlightScales {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_ba11);
    rng.set_stream(k as u64);
    let mut draw = |(lo, hi): (f64, f64)| lo + (hi - lo) * rng.random::<f64>();
    FlightScales { drag: draw(world.ball_drag), lift: draw(world.ball_lift) }
}

/// The physics ball `k` of `world` flies: the world's, with its own drag
/// and lift.
pub fn ball_physics(world: &World, cal: &Calibration, seed: u64, k: usize) -> Propagator {
    let prop = Propagator::new(world.physics.flight_model(), world.physics.bounce_model(), cal.table);
    prop.with_scales(ball_scales(world, seed, k))
}

/// `n` balls of `world` on the cell of `cal`, cycling through the nine
/// settings, seen by `tracker`; balls its launcher cannot aim are skipped.
pub fn simulate_world(world: &World, cal: &Calibration, seed: u64, n: usize, tracker: &TrackerModel) -> Vec<SimBall> {
    (0..n).filter_map(|k| simulate_world_ball(world, cal, seed, k, tracker)).collect()
}

/// Ball `k` of `world` (setting k mod 9), or `None` where its launcher
/// cannot aim it.
pub fn simulate_world_ball(
    world: &World,
    cal: &Calibration,
    seed: u64,
    k: usize,
    tracker: &TrackerModel,
) -> Option<SimBall> {
    let hit_x = cal.strike.hit_plane_x;
    let (mut rng_l, mut rng_t) = ball_rngs(seed, k);
    let ball = ball_physics(world, cal, seed, k);
    let l = launch_with(Setting::ALL[k % 9], world.axis, &ball, hit_x, &mut rng_l).ok()?;
    let truth = Truth::compute(&l, &ball, hit_x);
    let observations = observe(&truth, &ball, tracker, 0.0, &mut rng_t);
    Some(SimBall { index: k, truth, observations, physics: ball })
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::physics::Vec3;

    #[test]
    fn every_world_launches_valid_balls_with_skewed_axes() {
        let cal = Calibration::default_cell();
        for world in worlds(&cal) {
            world.physics.validate().unwrap();
            let balls = simulate_world(&world, &cal, 3, 18, &TrackerModel::default());
            // A lift of 1.47·S keeps some backspin balls off the table: skipped.
            assert!(balls.len() >= 9, "{}: {}", world.name, balls.len());
            for b in &balls {
                assert!(b.truth.bounce.is_some() && b.truth.hit.is_some(), "{}", world.name);
            }
            // Sidespin about the vertical: along the flight on a rising or falling ball.
            let side = &balls.iter().find(|b| b.index % 9 / 3 == 1).expect("a sidespin ball aims").truth;
            let (v, w) = (Vec3::from(side.launch.vel), Vec3::from(side.spin));
            assert!(w.x.hypot(w.y) < 0.4 * w.norm(), "{}: {w:?}", world.name);
            assert!(v.dot(&w).abs() > 1e-3 * v.norm() * w.norm(), "{}", world.name);
        }
    }

    #[test]
    fn balls_differ_by_their_own_drag_and_lift() {
        let cal = Calibration::default_cell();
        let w = &worlds(&cal)[0];
        let (a, b) = (ball_scales(w, 1, 0), ball_scales(w, 1, 1));
        assert_ne!(a, b);
        assert_eq!(a, ball_scales(w, 1, 0));
        assert!((BALL_DRAG.0..=BALL_DRAG.1).contains(&a.drag) && (BALL_LIFT.0..=BALL_LIFT.1).contains(&a.lift));
    }
}
