//! `qbricks-bake inspect`.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use files::output::QuietStdout;
use qbricks_preprocess::vdb::{inspect, VdbFile};

#[derive(clap::Args)]
pub struct Args {
    /// The OpenVDB file to describe.
    file: PathBuf,
    /// Print a JSON object (file_version, library_version, grids[...]) instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let file = VdbFile::open(&args.file)?;
    let report = inspect::report(&file)?;
    let mut out = QuietStdout::new();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &report).context("writing JSON")?;
        writeln!(out)?;
        return Ok(());
    }
    writeln!(
        out,
        "{}: OpenVDB file format {}, library {}, {} grid(s)",
        file.name(),
        report.file_version,
        report.library_version,
        report.grids.len()
    )?;
    for g in &report.grids {
        let range = match (g.min, g.max, g.max_magnitude) {
            (Some(Some(lo)), Some(Some(hi)), _) => format!("min {lo:.6}  max {hi:.6}"),
            (_, _, Some(Some(m))) => format!("max |v| {m:.6}"),
            _ => "empty".to_string(),
        };
        let mean: Vec<String> = g
            .mean
            .iter()
            .map(|m| m.map_or("-".into(), |m| format!("{m:.6}")))
            .collect();
        let bbox = match (g.bbox_min, g.bbox_max) {
            (Some(a), Some(b)) => format!("{a:?}..={b:?}"),
            _ => "-".into(),
        };
        let compression = if g.compression.is_empty() {
            "none".to_string()
        } else {
            g.compression.join("+")
        };
        writeln!(
            out,
            "\n  {:?}  {}{}",
            g.name,
            g.value_type,
            if g.half_float { " (half)" } else { "" }
        )?;
        writeln!(out, "    class        {}", g.class)?;
        writeln!(out, "    voxel size   {:?}", g.voxel_size)?;
        writeln!(out, "    translation  {:?}", g.translation)?;
        writeln!(out, "    compression  {compression}")?;
        writeln!(
            out,
            "    active       {} voxels, bbox {bbox}",
            g.active_voxels
        )?;
        writeln!(out, "    mean         [{}]  {range}", mean.join(", "))?;
        for (k, v) in &g.metadata {
            writeln!(out, "    meta {k:<14} {v}")?;
        }
    }
    Ok(())
}
