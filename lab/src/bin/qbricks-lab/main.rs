//! `qbricks-lab`: argument parsing and error reporting only; the work is in the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod accuracy;
mod bench;
mod synth;

#[derive(Parser)]
#[command(
    name = "qbricks-lab",
    version,
    about = "Analytic flows, accuracy against exact values, sampling benchmarks"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write an analytic test flow as a multi-grid VDB file.
    Synth(synth::Args),
    /// Bake an analytic flow at several resolutions and compare Q and speed with the exact values.
    Accuracy(accuracy::Args),
    /// Time and error of every sampling strategy at several steps against a fine reference.
    Bench(Box<bench::Args>),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Synth(args) => synth::run(args),
        Command::Accuracy(args) => accuracy::run(args),
        Command::Bench(args) => bench::run(*args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            if files::output::is_broken_pipe(err.as_ref()) {
                return ExitCode::SUCCESS;
            }
            eprintln!("qbricks-lab: {err:#}");
            ExitCode::from(2)
        }
    }
}
