//! `qbricks-view`: argument parsing and error reporting only; the work is in the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use ranks::Ranks;

mod info;
mod probe;
mod render;
mod render_sequence;
mod window;

#[derive(Parser)]
#[command(
    name = "qbricks-view",
    version,
    about = "Ray-cast .qbk brick files: a window to explore them, or headless render, probe, info",
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Without a subcommand: open the window.
    #[command(flatten)]
    window: window::Args,
}

#[derive(Subcommand)]
enum Command {
    /// Open the interactive window on a .qbk file (the default without a subcommand).
    Open(window::Args),
    /// Describe a .qbk file.
    Info(info::Args),
    /// Render a view to a PNG without a window.
    Render(Box<render::Args>),
    /// Print field values and gradients at points, or sample every field on a plane.
    Probe(probe::Args),
    /// Moved to `qbricks-lab bench`.
    #[command(hide = true)]
    Bench(Moved),
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
        None => ranks
            .one_process_only("the window")
            .and_then(|()| window::run(cli.window)),
        Some(Command::Open(args)) => ranks
            .one_process_only("the window")
            .and_then(|()| window::run(args)),
        Some(Command::Info(args)) => ranks
            .one_process_only("qbricks-view info")
            .and_then(|()| info::run(args)),
        // One file, or every frame of a sequence (each rendered as one file is; over the
        // ranks of an MPI run, each rank its share).
        Some(Command::Render(args)) => render::target(&args).and_then(|t| match t {
            render::Target::File(path) => render::run(*args, path, &ranks),
            render::Target::Sequence(path, pattern) => {
                render_sequence::run(&args, &path, pattern, &ranks)
            }
        }),
        Some(Command::Probe(args)) => ranks
            .one_process_only("qbricks-view probe")
            .and_then(|()| probe::run(args)),
        Some(Command::Bench(_)) => return moved("qbricks-view", "bench"),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            if files::output::is_broken_pipe(err.as_ref()) {
                return ExitCode::SUCCESS;
            }
            ranks.fail("qbricks-view", &err)
        }
    }
}
