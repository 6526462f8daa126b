//! `topspin replay FILE`: re-run a recorded session and compare its strike
//! plans bit for bit (DESIGN §8; the contract is in [`topspin_daemon::record`]).
//! Exit 0: every plan identical; 1: a plan differs (or one is missing);
//! 2: the file is not a usable recording.

use std::path::PathBuf;

use clap::Args;

use super::BadInput;
use topspin_daemon::record::{read_recording, replay_recording};
use topspin_daemon::viewer::view_recording;
use topspin_daemon::viewer::{LiveServer, ViewerSink};

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// A session recording (MCAP) written by `topspin run` with `[recording] enabled = true`.
    pub file: PathBuf,
    /// Print the report as one JSON object instead of a summary.
    #[arg(long)]
    pub json: bool,
    /// Then show the session in the live Foxglove view on ADDR (default
    /// 127.0.0.1:8765), replayed through the estimator as it ran.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = topspin_daemon::viewer::DEFAULT_LIVE_ADDR)]
    pub live: Option<std::net::SocketAddr>,
    /// With --live: recorded seconds per second (0: as fast as it goes).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// With --live: wait up to this long (s) for Foxglove to connect first.
    #[arg(long, default_value_t = 30.0)]
    pub live_wait: f64,
}

/// Serves the session in the live view (after the comparison).
fn live(
    args: &ReplayArgs,
    session: &topspin_daemon::record::Recording,
    addr: std::net::SocketAddr,
) -> anyhow::Result<()> {
    let server = LiveServer::start(addr, None).map_err(|e| BadInput(e.to_string()))?;
    eprintln!("live view on ws://{} (Foxglove: Open connection → Foxglove WebSocket)", server.addr());
    let start = topspin_daemon::clock::now();
    while server.clients() == 0 && topspin_daemon::clock::secs_since(start) < args.live_wait {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    std::thread::sleep(std::time::Duration::from_millis(500));
    let cal = session.calibration().map_err(|e| BadInput(e.to_string()))?;
    let mut sink = ViewerSink::new(&cal, Some(server), None, None).with_offset(session.log_time_offset);
    let stop = std::sync::atomic::AtomicBool::new(false);
    let speed = (args.speed > 0.0).then_some(args.speed);
    view_recording(session, &mut sink, speed, &stop).map_err(|e| BadInput(e.to_string()))?;
    eprintln!("live view: {} messages sent", sink.sent());
    Ok(())
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let session = read_recording(&args.file).map_err(|e| BadInput(e.to_string()))?;
    let report = replay_recording(&session).map_err(|e| BadInput(format!("{}: {e}", args.file.display())))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("recording    {}", args.file.display());
        if let Some(why) = &report.truncated {
            println!("truncated    yes ({why}); comparing what it holds");
        }
        println!("datagrams    {}", report.datagrams);
        let c = &report.ingest;
        println!(
            "accepted     {} (foreign {}, malformed {}, not valid {}, duplicate {}, out of order {})",
            report.accepted, c.foreign, c.malformed, c.not_valid, c.duplicate, c.out_of_order
        );
        println!("plans        {} recorded, {} replayed", report.recorded_plans, report.replayed_plans);
        println!("identical    {} of {} compared", report.identical, report.compared);
        println!("different    {}", report.different);
        if report.unmatched > 0 {
            let note = if report.truncated.is_some() { " (not compared: the file was cut off)" } else { "" };
            println!("unmatched    {}{note}", report.unmatched);
        }
        if let Some(d) = &report.first_difference {
            println!("first difference at plan {}: {}", d.index, d.fields.join(", "));
            println!("  recorded {}", d.recorded.as_deref().unwrap_or("-"));
            println!("  replayed {}", d.replayed.as_deref().unwrap_or("-"));
        }
    }
    if let Some(addr) = args.live {
        live(&args, &session, addr)?;
    }
    if report.identical() {
        Ok(())
    } else {
        anyhow::bail!(
            "replay differs from the recording: {} of {} plans differ, {} unmatched",
            report.different,
            report.compared,
            report.unmatched
        )
    }
}
