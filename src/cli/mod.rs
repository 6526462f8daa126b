//! The `topspin` command line (DESIGN §8): one module per subcommand, each a
//! thin shell over the library. Errors that make input unusable exit with
//! code 2 and one line on stderr naming the problem.

use clap::{Parser, Subcommand};

pub mod args;
pub mod bench;
pub mod bench_layout;
pub mod calibrate;
pub mod check;
pub mod crops;
pub mod demo;
pub mod doctor;
pub mod eval;
pub mod eval_paper;
pub mod eval_real;
pub mod fit;
pub mod identify;
pub mod logo;
pub mod logo_cnn;
pub mod mock_krc;
pub mod render;
pub mod replay;
pub mod replay_stream;
pub mod run;
pub mod sim;

/// Exit code for unusable input (files, configuration, arguments).
pub const EXIT_BAD_INPUT: i32 = 2;

/// An error that makes the input unusable: reported as one line, exit 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// A [`BadInput`] as the error a subcommand returns.
pub(crate) fn bad(msg: impl Into<String>) -> anyhow::Error {
    BadInput(msg.into()).into()
}

#[derive(Debug, Parser)]
#[command(name = "topspin", version, about = "Table-tennis robot controller that reads and answers spin")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
#[allow(clippy::large_enum_variant)] // parsed once at start-up
pub enum Command {
    /// The daemon: tracker in, RSI to the KR C4 out (systemd service).
    Run(run::RunArgs),
    /// Simulate launcher balls seen by the tracker: CSV + ground truth, or a
    /// live UDP stream.
    Sim(sim::SimArgs),
    /// Everything on loopback: simulated tracker, daemon, mock KR C4; judges every stroke.
    ///
    /// Example: `topspin demo --balls 27 --correction axis --json` (axis
    /// correction: AKorr from topspin's inverse kinematics).
    Demo(demo::DemoArgs),
    /// Spin and prediction for one recorded trajectory (CSV t,x,y,z).
    Fit(fit::FitArgs),
    /// Benchmarks of the running system.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Offline evaluations: accuracy tables on simulated and real flights.
    #[command(subcommand)]
    Eval(eval::EvalCommand),
    /// The mock KR C4: an RSI client sending <Rob> every 4 ms (12 ms).
    ///
    /// Example: `topspin mock-krc --correction axis --cycles 2500 --json`
    /// (the axis context: AKorr into AXISCORR; default RKorr into POSCORR).
    MockKrc(mock_krc::MockKrcArgs),
    /// Labelled synthetic ceiling-camera crops of simulated balls: PNG +
    /// labels, and/or a live TTI1 stream.
    Render(render::RenderArgs),
    /// Spin from a sequence of ball crops (the logo, background
    /// subtraction), or `logo eval` on rendered sequences.
    Logo(logo::LogoArgs),
    /// Re-run a recorded session (MCAP) and compare its plans bit for bit.
    Replay(replay::ReplayArgs),
    /// Commissioning checks: `check tracker` listens on the tracker port.
    #[command(subcommand)]
    Check(check::CheckCommand),
    /// Measure the robot's dead time and servo lag over RSI: a few mm of
    /// excitation from home, fitted from RIst; prints the `[servo]` lines
    /// for calib/robot.toml.
    ///
    /// Example: `topspin identify --axis all --amplitude-mm 3` (T1, reduced
    /// override; see rsi/README.md), then select and start topspin_rsi.src.
    Identify(identify::IdentifyArgs),
    /// Calibration from measurements: `calibrate cell` finds the table in
    /// the robot's BASE from touch points.
    ///
    /// Example: `topspin calibrate cell --points touches.csv --write calib`.
    #[command(subcommand)]
    Calibrate(calibrate::CalibrateCommand),
    /// Is this PC ready for the 4 ms RSI loop? Kernel, cores, rights, NIC,
    /// swap, time sync and a wake-up jitter probe on the RSI core.
    ///
    /// Example: `topspin doctor --config /etc/topspin/topspin.toml`.
    Doctor(doctor::DoctorArgs),
}

/// Offline commands end quietly when their reader goes away
/// (`topspin sim … | head`), as Unix tools do, instead of panicking on the
/// write. The daemon and the mock KR C4 keep Rust's default (SIGPIPE
/// ignored, a write error instead): a restarted journal must not kill them.
#[allow(unsafe_code)]
fn die_quietly_on_a_closed_pipe() {
    // SAFETY: sets one signal's disposition to its default, before this
    // process starts any thread.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// A command line clap cannot parse: one line and exit 2 (DESIGN §8);
/// help, version and a missing subcommand print as clap prints them.
fn usage_error(e: clap::Error) -> i32 {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let rendered = e.render().to_string();
    let mut lines = rendered.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with("For more information"));
    let first = lines.next().unwrap_or("bad command line").trim_start_matches("error: ");
    match lines.find(|l| l.starts_with('[') || l.starts_with("tip:")) {
        Some(extra) => eprintln!("topspin: {first} {extra}"),
        None => eprintln!("topspin: {first}"),
    }
    EXIT_BAD_INPUT
}

/// Runs the command line; returns the process exit code.
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => return usage_error(e),
    };
    if !matches!(cli.command, Command::Run(_) | Command::MockKrc(_) | Command::Identify(_)) {
        die_quietly_on_a_closed_pipe();
    }
    let result = match cli.command {
        Command::Run(a) => run::run(a),
        Command::Sim(a) => sim::run(a),
        Command::Fit(a) => fit::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Eval(c) => eval::run(c),
        Command::Bench(c) => bench::run(c),
        Command::MockKrc(a) => mock_krc::run(a),
        Command::Render(a) => render::run(a),
        Command::Logo(a) => logo::run(a),
        Command::Replay(a) => replay::run(a),
        Command::Check(c) => check::run(c),
        Command::Identify(a) => identify::run(a),
        Command::Doctor(a) => doctor::run(a),
        Command::Calibrate(c) => calibrate::run(c),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            if let Some(b) = e.downcast_ref::<BadInput>() {
                eprintln!("topspin: {b}");
                EXIT_BAD_INPUT
            } else {
                eprintln!("topspin: {e:#}");
                1
            }
        }
    }
}
