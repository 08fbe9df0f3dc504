//! `qbricks-view info`.

use std::io::Write;
use std::path::PathBuf;

use files::output::QuietStdout;
use format::{BrickFileView, OpenOptions};

#[derive(clap::Args)]
pub struct Args {
    /// The .qbk file to describe.
    pub file: PathBuf,
    /// Print JSON (stable keys: format_version, bytes, cells, bricks, regions, kd_nodes,
    /// levels, bounds_min, bounds_max, fields, source) instead of text.
    #[arg(long)]
    pub json: bool,
    /// Skip the payload checksum (faster on huge files; the archive is still validated).
    #[arg(long)]
    pub no_checksum: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let options = OpenOptions {
        verify_checksum: !args.no_checksum,
        structure: format::Structure::AtOpen,
    };
    let view = BrickFileView::open_with(&args.file, &options)?;
    let info = qbricks_viewer::info::info(&view);
    let mut out = QuietStdout::new();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &info)?;
        writeln!(out)?;
    } else {
        out.write_all(qbricks_viewer::info::to_text(&info).as_bytes())?;
    }
    out.flush()?;
    Ok(())
}
