//! `topspin replay FILE`: re-run a recorded session and compare its strike
//! plans bit for bit (DESIGN §8; the contract is in [`crate::record`]).
//! Exit 0: every plan identical; 1: a plan differs (or one is missing);
//! 2: the file is not a usable recording.

use std::path::PathBuf;

use clap::Args;

use super::BadInput;
use crate::record::{read_session, replay::replay_session};

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// A session recording (MCAP) written by `topspin run` with `[recording] enabled = true`.
    pub file: PathBuf,
    /// Print the report as one JSON object instead of a summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let session = read_session(&args.file).map_err(|e| BadInput(e.to_string()))?;
    let report = replay_session(&session).map_err(|e| BadInput(format!("{}: {e}", args.file.display())))?;
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
