//! The MPI launcher set (real trajectories, `../shared/data/mpi-launcher`
//! or `$TOPSPIN_MPI_DATA`): loading, the lab → table frame, bounce
//! detection, the baseline evaluation and the calibration. Each test skips
//! with a note when the data is absent. Bounds here are loose sanity
//! bounds, not tuned numbers; `docs/real-data.md` has the numbers.
//!
//! `cargo test --test real_data -- --nocapture` prints the full report.

use std::path::Path;

use topspin_core::physics::{PhysicsParams, Propagator, Table};
use topspin_lab::data::{BALL_RADIUS, BounceSearch, MPI_LAB_TO_TABLE, detect_bounces, estimate_frame};
use topspin_lab::data::{CalibrationSetup, calibrate, split_even_odd};
use topspin_lab::data::{CubicBaseline, EvalConfig, evaluate, prepare};
use topspin_lab::data::{RealTrajectory, SETS, load, locate, sampling_stats};

fn data() -> Option<Vec<RealTrajectory>> {
    let Some(dir) = locate(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")) else {
        eprintln!(
            "note: MPI launcher data not found (set TOPSPIN_MPI_DATA or place shared/ beside the repo); skipping"
        );
        return None;
    };
    Some(load(&dir).expect("the MPI set loads"))
}

fn paper_cfg() -> EvalConfig {
    let p = PhysicsParams::paper();
    EvalConfig::new(Propagator::new(p.flight_model(), p.bounce_model(), Table::default()))
}

#[test]
fn loads_every_set_with_plausible_sampling() {
    let Some(trajs) = data() else { return };
    assert_eq!(trajs.len(), 88);
    for set in SETS {
        let members: Vec<_> = trajs.iter().filter(|t| t.set == set).collect();
        assert!(!members.is_empty(), "{set}");
        let s = sampling_stats(&members, MPI_LAB_TO_TABLE.origin[2] + 0.1);
        println!(
            "{set:<14} n={:>2} samples {:>5} dt median {:.2} ms max {:.1} ms gaps {:>3} duration {:.3}-{:.3} s noise rms (mm) {:.2} {:.2} {:.2}",
            s.trajectories,
            s.samples,
            1e3 * s.median_dt,
            1e3 * s.max_dt,
            s.gaps,
            s.duration.0,
            s.duration.1,
            1e3 * s.noise_rms.x,
            1e3 * s.noise_rms.y,
            1e3 * s.noise_rms.z
        );
        // ~180 Hz, millimetre-level noise.
        assert!((0.004..0.007).contains(&s.median_dt), "{s:?}");
        assert!(s.noise_rms.iter().all(|n| *n < 0.01), "{s:?}");
    }
}

#[test]
fn frame_estimate_is_sane_and_matches_the_constant() {
    let Some(trajs) = data() else { return };
    let f = estimate_frame(&trajs);
    println!("{f:#?}");
    let c = MPI_LAB_TO_TABLE;
    // Surface fitted from most trajectories, close to the constant in use.
    assert!(f.bounces >= 70, "{f:?}");
    assert!((f.surface_z - c.origin[2]).abs() < 0.003, "{f:?}");
    assert!(f.surface_spread < 0.01, "{f:?}");
    // The constant's net lies within the bounds the data gives.
    let net = c.origin[0];
    assert!(f.net_x_bounds.0 <= net && net <= f.net_x_bounds.1, "{f:?}");
    assert!(net < f.net_clearance_x, "{f:?}");
    // Shots fly along +x within a few degrees.
    assert!(f.heading.abs() < 3f64.to_radians(), "{f:?}");
}

#[test]
fn every_launcher_bounce_is_on_the_robots_half() {
    let Some(trajs) = data() else { return };
    let table = Table::default();
    let mut found = 0;
    for tr in &trajs {
        let s = MPI_LAB_TO_TABLE.samples(&tr.samples);
        let bounces = detect_bounces(&s, &BounceSearch::table());
        if let Some(b) = bounces.first() {
            found += 1;
            println!(
                "{:<18} bounce t {:.4} s at ({:+.3}, {:+.3}, {:+.4}) m, vz in {:+.2} out {:+.2} (e ≈ {:.2}), refined {}, later contacts {}",
                tr.name(),
                b.t,
                b.pos.x,
                b.pos.y,
                b.pos.z,
                b.vel_in.z,
                b.vel_out.z,
                -b.vel_out.z / b.vel_in.z,
                b.refined,
                bounces.len() - 1
            );
            assert!(b.pos.x > 0.0 && b.pos.x < table.robot_end_x(), "{} bounces at {:?}", tr.name(), b.pos);
            assert!(b.pos.y.abs() < table.width / 2.0, "{}", tr.name());
            assert!((b.pos.z - BALL_RADIUS).abs() < 0.015, "{}", tr.name());
        } else {
            println!("{:<18} no bounce in the recording", tr.name());
        }
    }
    assert!(found >= 70, "{found}");
}

#[test]
fn baseline_harness_runs_with_sane_errors() {
    let Some(trajs) = data() else { return };
    let prepared = prepare(&trajs, &MPI_LAB_TO_TABLE);
    let rep = evaluate(&prepared, &CubicBaseline, &paper_cfg());
    println!("baseline (cubic, spin 0, paper physics):\n{rep}");
    assert!(rep.all.used >= 80, "{rep}");
    assert!(rep.all.bounce.count >= 60, "{rep}");
    assert!(rep.all.bounce.median < 150.0, "{rep}");
    assert!(rep.all.ahead.count >= 30, "{rep}");
    assert!(rep.all.ahead.median < 300.0, "{rep}");
}

#[test]
fn calibration_of_drag_and_bounce_does_not_hurt_validation() {
    let Some(trajs) = data() else { return };
    // Spin-free shots only: with the spin fixed at zero, the spin sets
    // would bend C_D to absorb their Magnus force.
    let prepared: Vec<_> =
        prepare(&trajs, &MPI_LAB_TO_TABLE).into_iter().filter(|t| t.set.ends_with("no_spin")).collect();
    let (train, validation) = split_even_odd(&prepared);
    let setup = CalibrationSetup::drag_and_bounce(PhysicsParams::paper());
    let r = calibrate(&train, &validation, |_| CubicBaseline, &paper_cfg(), &setup);
    println!(
        "calibrated {:?} in {} evaluations\n  train objective {:.1} -> {:.1} mm, validation {:.1} -> {:.1} mm",
        r.values, r.evaluations, r.train_before, r.train_after, r.validation_before, r.validation_after
    );
    println!("train:\n{}validation:\n{}", r.train, r.validation);
    assert!(r.train_after <= r.train_before + 1e-9);
    assert!(r.params.validate().is_ok());
    // Not a fit to noise: the held-out half improves too (or at worst
    // stays within a few mm).
    assert!(r.validation_after < r.validation_before + 5.0, "{r:?}");
}

/// The numbers in `docs/real-data.md`: `cargo test --release --test
/// real_data -- --ignored --nocapture`.
#[test]
#[ignore = "prints the report for docs/real-data.md"]
fn report_for_the_docs() {
    use topspin_lab::data::LabToTable;
    use topspin_lab::data::{CalibParam, Objective};
    let Some(trajs) = data() else { return };
    let prepared = prepare(&trajs, &MPI_LAB_TO_TABLE);
    for horizon in [0.2, 0.3] {
        let mut cfg = paper_cfg();
        cfg.horizon = horizon;
        println!("baseline, horizon {horizon} s:\n{}", evaluate(&prepared, &CubicBaseline, &cfg));
    }
    // Sensitivity to the net's placement (which samples count as pre-net).
    for dx in [-0.1, 0.1] {
        let mut f: LabToTable = MPI_LAB_TO_TABLE;
        f.origin[0] += dx;
        let rep = evaluate(&prepare(&trajs, &f), &CubicBaseline, &paper_cfg());
        println!("net moved by {dx:+} m:\n{rep}");
    }
    // Calibrate on the spin-free shots only: with spin fixed at zero, the
    // spin sets would bend C_D to absorb their Magnus force.
    let no_spin: Vec<_> = prepared.iter().filter(|t| t.set.ends_with("no_spin")).cloned().collect();
    let (train, validation) = split_even_odd(&no_spin);
    for objective in [Objective::MedianSum, Objective::MeanSum] {
        let mut setup = CalibrationSetup::drag_and_bounce(PhysicsParams::paper());
        setup.objective = objective;
        setup.max_evals = 300;
        setup.tolerance = 0.01;
        let r = calibrate(&train, &validation, |_| CubicBaseline, &paper_cfg(), &setup);
        println!(
            "{objective:?}: {:?} in {} evaluations; train {:.1} -> {:.1} mm, validation {:.1} -> {:.1} mm\ntrain:\n{}validation:\n{}",
            r.values,
            r.evaluations,
            r.train_before,
            r.train_after,
            r.validation_before,
            r.validation_after,
            r.train,
            r.validation
        );
        let all =
            topspin_lab::data::evaluate_with(&prepared, &|_: &PhysicsParams| CubicBaseline, &paper_cfg(), &r.params);
        println!("all sets with these constants:\n{all}");
    }
    // Drag alone.
    let mut setup = CalibrationSetup::drag_and_bounce(PhysicsParams::paper());
    setup.params = vec![CalibParam::DragCoefficient];
    let r = calibrate(&train, &validation, |_| CubicBaseline, &paper_cfg(), &setup);
    println!(
        "C_D only: {:?}; train {:.1} -> {:.1}, validation {:.1} -> {:.1}",
        r.values, r.train_before, r.train_after, r.validation_before, r.validation_after
    );
}

/// With the fitted spin, the bounce point of the spin shots is
/// predicted better than without it (the refined fit with the spin held at
/// zero, and the cubic baseline), under the shipped physics. Loose bounds.
#[test]
fn fitted_spin_beats_no_spin_on_the_spin_sets() {
    use topspin_core::calib::Calibration;
    use topspin_lab::data::FitPredictor;
    use topspin_lab::data::eval_config;
    let Some(trajs) = data() else { return };
    let prepared = prepare(&trajs, &MPI_LAB_TO_TABLE);
    let p = Calibration::default_cell().physics;
    let cfg = eval_config(&p, 0.2);
    let spin = evaluate(&prepared, &FitPredictor::refined(&p), &cfg);
    let no_spin = evaluate(&prepared, &FitPredictor::no_spin(&p), &cfg);
    let cubic = evaluate(&prepared, &CubicBaseline, &cfg);
    println!("refined fit:\n{spin}refined, spin 0:\n{no_spin}cubic, spin 0:\n{cubic}");
    for set in ["backspin", "topspin"] {
        let g = |r: &topspin_lab::data::Report| r.sets.iter().find(|g| g.name == set).unwrap().clone();
        let (s, n, c) = (g(&spin), g(&no_spin), g(&cubic));
        assert!(s.bounce.count >= 3 && s.ahead.count >= 10, "{set}: {s:?}");
        assert!(s.bounce.median < 0.75 * n.bounce.median, "{set}: spin {} vs no spin {}", s.bounce, n.bounce);
        assert!(s.bounce.median < 0.75 * c.bounce.median, "{set}: spin {} vs cubic {}", s.bounce, c.bounce);
        assert!(s.bounce.median < 100.0, "{set}: {}", s.bounce);
        assert!(s.ahead.median < n.ahead.median, "{set}: 0.2 s ahead, spin {} vs no spin {}", s.ahead, n.ahead);
    }
    // Spin shots read as spin of the right sign; spin-free ones as little.
    let wy = |set: &str| {
        let mut v: Vec<f64> =
            spin.results.iter().filter(|r| r.set == set).filter_map(|r| r.prediction.map(|p| p.state.spin.y)).collect();
        topspin_lab::data::median(&mut v)
    };
    assert!(wy("backspin") < -50.0 && wy("topspin") > 50.0, "{} {}", wy("backspin"), wy("topspin"));
    assert!(wy("robot_no_spin").abs() < 50.0, "{}", wy("robot_no_spin"));
}

/// The lift calibration runs on all sets with the refined fit and does not
/// get worse on its training half (a smoke check: a handful of evaluations
/// on a few files; the full search is `topspin eval real --calibrate` or
/// the ignored test below).
#[test]
fn lift_calibration_smoke() {
    use topspin_lab::data::{LiftChoice, calibrate_lift};
    let Some(trajs) = data() else { return };
    let prepared: Vec<_> = prepare(&trajs, &MPI_LAB_TO_TABLE).into_iter().filter(|t| t.index < 4).collect();
    let r = calibrate_lift(&prepared, &PhysicsParams::paper(), LiftChoice::Saturating, 8);
    println!("{r:?}");
    assert!(r.train_after <= r.train_before + 1e-9);
    assert!(r.params.validate().is_ok());
    assert_eq!(r.values.len(), 5);
}

/// The calibration behind `calib/physics.toml` (a minute or two in release
/// mode): `cargo test --release --test real_data -- --ignored --nocapture
/// full_lift_calibration` prints what `topspin eval real --calibrate` does.
#[test]
#[ignore = "the full calibration; slow"]
fn full_lift_calibration() {
    use topspin_lab::data::{LiftChoice, calibrate_lift, calibration_markdown, objective};
    let Some(trajs) = data() else { return };
    let prepared = prepare(&trajs, &MPI_LAB_TO_TABLE);
    let (train, validation) = split_even_odd(&prepared);
    let shipped = topspin_core::calib::Calibration::default_cell().physics;
    println!(
        "shipped calib/: objective train {:.1} mm, validation {:.1} mm",
        objective(&train, &shipped),
        objective(&validation, &shipped)
    );
    for (lift, name) in [(LiftChoice::Constant, "constant lift"), (LiftChoice::Saturating, "saturating lift")] {
        let r = calibrate_lift(&prepared, &PhysicsParams::paper(), lift, 250);
        print!("{}", calibration_markdown(name, &r));
        assert!(r.train_after <= r.train_before + 1e-9);
        assert!(r.validation_after < r.validation_before + 5.0, "{r:?}");
    }
}
