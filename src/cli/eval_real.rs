//! `topspin eval real`: the issue-2 real-data tables on the MPI launcher
//! set: bounce point and position 0.3 s / 0.2 s ahead from the pre-net
//! samples, with the fitted spin and without, under the paper's and the
//! calibrated physics; with `--calibrate`, the calibration of C_D, lift, e
//! and μ is rerun (a minute or two) and its results are compared too.

use std::path::{Path, PathBuf};

use clap::Args;
use serde_json::json;

use super::BadInput;
use super::fit::{PhysicsChoice, load_calibration};
use topspin_core::physics::PhysicsParams;
use topspin_lab::data::MPI_LAB_TO_TABLE;
use topspin_lab::data::SpinFit;
use topspin_lab::data::prepare;
use topspin_lab::data::{DATA_ENV, load, locate};
use topspin_lab::data::{
    LiftChoice, PREDICTORS, Variant, Which, calibrate_lift, calibration_markdown, compare, markdown, params_json,
    rows_json, spin_markdown, spin_summary,
};

#[derive(Debug, Args)]
pub struct EvalRealArgs {
    /// The MPI launcher folder (default: $TOPSPIN_MPI_DATA, else
    /// ../shared/data/mpi-launcher from the repository root).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Rerun the calibration (constant and saturating lift) and compare its
    /// results as well.
    #[arg(long)]
    pub calibrate: bool,
    /// Most objective evaluations per calibration.
    #[arg(long, default_value_t = 250, value_name = "N")]
    pub max_evals: usize,
    /// Only this physics (default: the paper's and the calibrated).
    #[arg(long, value_enum)]
    pub physics: Option<PhysicsChoice>,
    /// Another calibration folder for "calibrated".
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// One JSON object instead of Markdown.
    #[arg(long)]
    pub json: bool,
}

fn data_dir(explicit: Option<&Path>) -> Result<PathBuf, BadInput> {
    if let Some(d) = explicit {
        return if d.join("index.csv").is_file() {
            Ok(d.to_owned())
        } else {
            Err(BadInput(format!("{}: no MPI launcher data (index.csv missing)", d.display())))
        };
    }
    let roots = [std::env::current_dir().ok(), Some(PathBuf::from(env!("CARGO_MANIFEST_DIR")))];
    roots.iter().flatten().find_map(|r| locate(r)).ok_or_else(|| {
        BadInput(format!(
            "MPI launcher data not found: pass --data DIR, set {DATA_ENV}, or place it at ../shared/data/mpi-launcher"
        ))
    })
}

pub fn run_real(a: EvalRealArgs) -> anyhow::Result<()> {
    let started = topspin_daemon::clock::now();
    let dir = data_dir(a.data.as_deref())?;
    let trajs = load(&dir).map_err(|e| BadInput(e.to_string()))?;
    let prepared = prepare(&trajs, &MPI_LAB_TO_TABLE);
    let calibrated = load_calibration(a.calib.as_deref(), PhysicsChoice::Calibrated)?.physics;

    let mut variants = Vec::new();
    if a.physics != Some(PhysicsChoice::Calibrated) {
        variants.push(Variant { name: "paper".into(), params: PhysicsParams::paper() });
    }
    if a.physics != Some(PhysicsChoice::Paper) {
        variants.push(Variant { name: "calibrated (calib/)".into(), params: calibrated });
    }
    let mut calibrations = Vec::new();
    if a.calibrate {
        for (lift, name) in [(LiftChoice::Constant, "constant lift"), (LiftChoice::Saturating, "saturating lift")] {
            let r = calibrate_lift(&prepared, &PhysicsParams::paper(), lift, a.max_evals);
            variants.push(Variant { name: format!("fitted, {name}"), params: r.params.clone() });
            calibrations.push((name, r));
        }
    }
    let rows = compare(&prepared, &variants, &PREDICTORS);
    let spin_row = rows
        .iter()
        .rev()
        .find(|r| r.predictor == Which::Fit(SpinFit::Refined) && r.physics != "paper")
        .or_else(|| rows.iter().find(|r| r.predictor == Which::Fit(SpinFit::Refined)));
    let spins = spin_row.map(|r| (r.physics.clone(), spin_summary(&prepared, &r.predictions)));
    let elapsed = topspin_daemon::clock::secs_since(started);

    if a.json {
        let out = json!({
            "data": dir.display().to_string(),
            "trajectories": prepared.len(),
            "variants": variants.iter().map(|v| json!({"name": v.name, "physics": params_json(&v.params)})).collect::<Vec<_>>(),
            "calibrations": calibrations.iter().map(|(name, r)| json!({
                "lift": name,
                "values": r.values.iter().map(|(k, v)| (k.name().to_owned(), json!(v))).collect::<serde_json::Map<_, _>>(),
                "evaluations": r.evaluations,
                "train_before_mm": r.train_before, "train_after_mm": r.train_after,
                "validation_before_mm": r.validation_before, "validation_after_mm": r.validation_after,
            })).collect::<Vec<_>>(),
            "rows": rows_json(&rows),
            "spin_rps": spins.as_ref().map(|(physics, s)| json!({
                "physics": physics,
                "sets": s.iter().map(|x| json!({"set": x.set, "count": x.count, "median_norm": x.norm,
                    "median_components": x.components, "y_range": [x.y_range.0, x.y_range.1]})).collect::<Vec<_>>(),
            })),
            "seconds": elapsed,
        });
        println!("{out}");
        return Ok(());
    }
    println!(
        "Real launcher trajectories ({}, {} files): predictions from the samples before the net.",
        dir.display(),
        prepared.len()
    );
    for v in &variants {
        let p = &v.params;
        println!(
            "- physics `{}`: C_D {:.3}, lift {:?}, e {:.3}, μ {:.3}",
            v.name, p.drag_coefficient, p.lift, p.restitution, p.friction
        );
    }
    if !calibrations.is_empty() {
        println!(
            "\nCalibration (refined spin fit; objective: per set, median bounce error + median error 0.2 s ahead, \
             averaged over the four sets; train = even file indices, validation = odd):\n"
        );
        for (name, r) in &calibrations {
            print!("{}", calibration_markdown(name, r));
        }
    }
    print!("{}", markdown(&rows));
    if let Some((physics, s)) = &spins {
        println!("\nFitted spin per set (refined fit, physics `{physics}`):\n");
        print!("{}", spin_markdown(s));
    }
    println!("\n({elapsed:.1} s)");
    Ok(())
}
