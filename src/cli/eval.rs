#[derive(Debug, clap::Subcommand)]
pub enum EvalCommand {
    Fit,
}
pub fn run(_a: EvalCommand) -> anyhow::Result<()> {
    todo!()
}
