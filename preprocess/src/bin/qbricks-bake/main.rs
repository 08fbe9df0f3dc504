//! `qbricks-bake`: argument parsing and error reporting only; the work is in the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod accuracy;
mod bake;
mod inspect;
mod sequence;
mod synth;

#[derive(Parser)]
#[command(
    name = "qbricks-bake",
    version,
    about = "OpenVDB velocity grids → .qbk brick files"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Describe the grids of a VDB file.
    Inspect(inspect::Args),
    /// Write an analytic test flow as a multi-grid VDB file.
    Synth(synth::Args),
    /// Bake a VDB file into a .qbk brick file.
    Bake(bake::Args),
    /// Bake an analytic flow at several resolutions and compare Q and speed with the exact values.
    Accuracy(accuracy::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Inspect(args) => inspect::run(args),
        Command::Synth(args) => synth::run(args),
        Command::Bake(args) => bake::run(args),
        Command::Accuracy(args) => accuracy::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            if files::output::is_broken_pipe(err.as_ref()) {
                return ExitCode::SUCCESS;
            }
            eprintln!("qbricks-bake: {err:#}");
            ExitCode::from(2)
        }
    }
}
