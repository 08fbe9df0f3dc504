//! `qbricks-bake synth`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`synth` is not implemented yet")
}
