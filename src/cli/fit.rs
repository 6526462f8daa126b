#[derive(Debug, clap::Args)]
pub struct FitArgs {}
pub fn run(_a: FitArgs) -> anyhow::Result<()> {
    todo!()
}
