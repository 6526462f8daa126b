#[derive(Debug, clap::Args)]
pub struct SimArgs {}
pub fn run(_a: SimArgs) -> anyhow::Result<()> {
    todo!()
}
