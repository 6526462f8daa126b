//! Spin from a flight, as a lab checks the fit before it trusts it: nine
//! simulated launcher balls (one per setting, seeded), seen by the
//! tracker model until the net, fitted with the paper's polynomial and
//! Magnus fit refined by the flight model, and compared with the truth.
//!
//! `cargo run --release --example spin_fit`

use topspin_core::calib::Calibration;
use topspin_core::fit::{FitConfig, Method, Sample, fit_trajectory};
use topspin_core::physics::{Vec3, rad_to_rps};
use topspin_sim::{Setting, TrackerModel, simulate_ball};

fn main() {
    let cal = Calibration::default_cell();
    let prop = cal.propagator();
    let hit_x = cal.strike.hit_plane_x;
    let cfg = FitConfig::new(Method::Refined, hit_x).with_variation(cal.physics.variation);
    println!("| setting | true spin, rps | fitted spin, rps | error, rps |");
    println!("|---|---|---|---|");
    for (k, setting) in Setting::ALL.into_iter().enumerate() {
        let ball = simulate_ball(1, k, setting, &prop, hit_x, &TrackerModel::default()).expect("a valid shot");
        // What the robot has when it must commit: the flight up to the net.
        let samples: Vec<Sample> =
            ball.observations.iter().filter(|o| o.pos.x < 0.0).map(|o| Sample::new(o.t, o.pos)).collect();
        let truth = Vec3::from(ball.truth.launch.spin);
        match fit_trajectory(&samples, &prop, &cfg) {
            Ok(fit) => println!(
                "| {setting} | {} | {} | {:.1} |",
                rps(truth),
                rps(fit.spin),
                rad_to_rps((fit.spin - truth).norm())
            ),
            Err(e) => println!("| {setting} | {} | no fit: {e} | |", rps(truth)),
        }
    }
}

fn rps(w: Vec3) -> String {
    format!("[{:.1} {:.1} {:.1}]", rad_to_rps(w.x), rad_to_rps(w.y), rad_to_rps(w.z))
}
