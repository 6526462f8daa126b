//! `topspin render`: placeholder, filled in below.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {}
pub fn run(_a: RenderArgs) -> anyhow::Result<()> {
    Ok(())
}
