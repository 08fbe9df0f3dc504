//! `qbricks-bake`: argument parsing and error reporting only; the work is in the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use qbricks_preprocess::sequence::input_pattern;
use ranks::Ranks;

mod bake;
mod inspect;
mod sequence;

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
    /// Bake a VDB file into a .qbk brick file.
    Bake(bake::Args),
    /// Moved to `qbricks-lab synth`.
    #[command(hide = true)]
    Synth(Moved),
    /// Moved to `qbricks-lab accuracy`.
    #[command(hide = true)]
    Accuracy(Moved),
}

/// The arguments of a command that moved to `qbricks-lab`, taken whole so that the message
/// says where it went whatever they were.
#[derive(clap::Args)]
struct Moved {
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
    args: Vec<String>,
}

/// Exit code 2 with where a command went: `qbricks-lab` runs it with the same arguments.
fn moved(prog: &str, sub: &str) -> ExitCode {
    eprintln!("{prog}: {sub}: moved: run `qbricks-lab {sub} …` (same arguments)");
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // The ranks of an MPI run (built with the `mpi` feature), else this one process.
    let ranks = Ranks::init();
    let result = match cli.command {
        Command::Inspect(args) => ranks
            .one_process_only("qbricks-bake inspect")
            .and_then(|()| inspect::run(args)),
        // One file, or every frame of a sequence (which bakes each as one file; over the
        // ranks of an MPI run, each rank its share of the frames, or of one file's fields).
        Command::Bake(args) => {
            bake::plan(&args).and_then(|plan| match input_pattern(&args.input)? {
                Some(pattern) => sequence::run(&args, pattern, &plan.bake, plan.start, &ranks),
                // One file over ranks: each derives its share of the fields, rank 0
                // writes the file.
                None => bake::run(args, plan, &ranks),
            })
        }
        Command::Synth(_) => return moved("qbricks-bake", "synth"),
        Command::Accuracy(_) => return moved("qbricks-bake", "accuracy"),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            if files::output::is_broken_pipe(err.as_ref()) {
                return ExitCode::SUCCESS;
            }
            ranks.fail("qbricks-bake", &err)
        }
    }
}
