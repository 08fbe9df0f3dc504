//! `qbricks-view probe`.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context};
use files::input::{read_whole, Limits};
use files::output::QuietStdout;
use qbricks_viewer::probe;
use qbricks_viewer::volume::Volume;

#[derive(clap::Args)]
pub struct Args {
    /// Brick file to probe.
    pub file: PathBuf,
    /// CSV file of points, one `x,y,z` per line (optional header line).
    #[arg(long, conflicts_with = "line")]
    pub points: Option<PathBuf>,
    /// Evenly spaced points on a segment: x0,y0,z0:x1,y1,z1:N.
    #[arg(long, allow_hyphen_values = true)]
    pub line: Option<String>,
    /// Field whose gradient is reported [default: q, else the first field].
    #[arg(long)]
    pub field: Option<String>,
    /// Print a JSON list (one object per point) instead of CSV.
    #[arg(long)]
    pub json: bool,
}

/// Largest points CSV read (regular file, device or pipe): 1 GiB of text is about 30 M
/// points, far more than a probe is for.
const MAX_CSV_BYTES: u64 = 1 << 30;

pub fn run(args: Args) -> anyhow::Result<()> {
    let points = match (&args.points, &args.line) {
        (Some(p), None) => {
            let bytes = read_whole(p, Limits::both(MAX_CSV_BYTES))?;
            let text = std::str::from_utf8(&bytes)
                .map_err(|e| anyhow::anyhow!("{}: not UTF-8 text: {e}", p.display()))?;
            probe::parse_points_csv(text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?
        }
        (None, Some(l)) => probe::parse_line(l).map_err(|e| anyhow::anyhow!("--line: {e}"))?,
        _ => bail!("expected exactly one of --points CSV or --line x0,y0,z0:x1,y1,z1:N"),
    };
    let view = format::BrickFileView::open(&args.file)?;
    let vol = Volume::new(&view).with_context(|| format!("{}", args.file.display()))?;
    if vol.fields.is_empty() {
        bail!("{}: the file has no fields", args.file.display());
    }
    let gf = match &args.field {
        Some(name) => vol
            .field_index(name)
            .with_context(|| format!("{}", args.file.display()))?,
        None => probe::default_field(&vol),
    };
    let mut out = std::io::BufWriter::new(QuietStdout::new());
    let format = if args.json {
        probe::ReportFormat::Json
    } else {
        probe::ReportFormat::Csv
    };
    probe::write_report(&mut out, &vol, &points, gf, format)?;
    out.flush()?;
    Ok(())
}
