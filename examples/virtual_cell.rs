//! The whole cell on a virtual clock, the way a lab tries a change before
//! it meets the robot: simulated tracker datagrams → ingest → estimator →
//! RSI session ↔ mock KR C4 (dead time, lag, limits), every stroke judged
//! on the true ball and its return flown to where it lands. No sockets,
//! no threads, no sleeps: the same seed gives the same session.
//!
//! `cargo run --release --example virtual_cell [BALLS] [SEED]`

use topspin_core::calib::Calibration;
use topspin_sim::demo::DemoConfig;
use topspin_sim::virtual_cell::run_virtual;

fn main() {
    let mut args = std::env::args().skip(1).map(|a| a.parse::<u64>().expect("BALLS and SEED are integers"));
    let balls = args.next().unwrap_or(9) as usize;
    let seed = args.next().unwrap_or(1);
    let cal = Calibration::default_cell();
    let run = run_virtual(&DemoConfig { balls, seed, ..DemoConfig::default() }, &cal);
    let returned = run.per_ball.iter().filter(|b| b.returned).count();
    println!(
        "{balls} balls, seed {seed}: {} reachable, {} hit, {returned} returned; {} RSI cycles, {} late",
        run.reachable(),
        run.hits(),
        run.mock.cycles,
        run.mock.late
    );
}
