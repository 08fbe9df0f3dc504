//! `qbricks-view`: argument parsing and error reporting only; the work is in the library.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod info;
mod probe;
mod render;

#[derive(Parser)]
#[command(name = "qbricks-view", version, about = "Ray-cast .qbk brick files")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Describe a .qbk file.
    Info(info::Args),
    /// Render a view to a PNG without a window.
    Render(Box<render::Args>),
    /// Print field values and gradients at points.
    Probe(probe::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(args) => info::run(args),
        Command::Render(args) => render::run(*args),
        Command::Probe(args) => probe::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            if is_broken_pipe(&err) {
                return ExitCode::SUCCESS;
            }
            eprintln!("qbricks-view: {err:#}");
            ExitCode::from(2)
        }
    }
}

/// Whether the run failed because its stdout reader went away (output through
/// `QuietStdout` never fails that way; this catches any other path, including a broken pipe
/// wrapped in a JSON serialisation error). Such a run ends quietly with status 0.
fn is_broken_pipe(err: &anyhow::Error) -> bool {
    let broken = Some(std::io::ErrorKind::BrokenPipe);
    err.chain().any(|e| {
        e.downcast_ref::<std::io::Error>().map(std::io::Error::kind) == broken
            || e.downcast_ref::<serde_json::Error>()
                .and_then(serde_json::Error::io_error_kind)
                == broken
    })
}
