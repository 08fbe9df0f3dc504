//! `qbricks-bake synth`.

use std::path::PathBuf;
use std::time::Instant;

use std::io::Write;

use anyhow::Context;
use clap::ValueEnum;
use format::output::QuietStdout;
use qbricks_preprocess::synth::{write_scene, SynthOptions};
use qbricks_preprocess::vdb::write::Compression;

#[derive(Clone, Copy, ValueEnum)]
pub enum CompressionArg {
    /// zlib over the active values (OpenVDB's usual setting without Blosc).
    Zip,
    /// Active values only, no zlib.
    Mask,
    /// Every value of every node, raw.
    None,
}

#[derive(clap::Args)]
pub struct Args {
    /// Scene: wake (nested boxes), wake-single, lamb-oseen, burgers or abc.
    pub scene: String,
    /// Output VDB file (written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Voxels along the longest axis of the coarsest grid.
    #[arg(long, default_value_t = 64)]
    pub n0: u32,
    /// Number of nested levels, each refined by 2 (wake only; single-grid scenes ignore it).
    #[arg(long, default_value_t = 3)]
    pub levels: u32,
    /// Node-value compression.
    #[arg(long, value_enum, default_value_t = CompressionArg::Zip)]
    pub compression: CompressionArg,
    /// Also write the speed |u| of every velocity grid as a float grid (speed_l<k>).
    #[arg(long)]
    pub float: bool,
    /// Write velocity as a MAC grid (class "staggered": component c on the lower face
    /// along axis c, OpenVDB's convention).
    #[arg(long)]
    pub staggered: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let start = Instant::now();
    let opts = SynthOptions {
        scene: args.scene.clone(),
        n0: args.n0,
        levels: args.levels,
        compression: match args.compression {
            CompressionArg::Zip => Compression::Zip,
            CompressionArg::Mask => Compression::ActiveMask,
            CompressionArg::None => Compression::None,
        },
        speed_grids: args.float,
        staggered: args.staggered,
    };
    let (grids, bytes) =
        write_scene(&args.output, &opts).with_context(|| format!("synth {}", args.scene))?;
    let mut out = QuietStdout::new();
    for g in &grids {
        writeln!(
            out,
            "{:<10} {:<6} voxel {:<10.6} active voxels {:>10} leaves {:>7}",
            g.name, g.value_type, g.voxel_size, g.active_voxels, g.leaves
        )?;
    }
    let voxels: u64 = grids.iter().map(|g| g.active_voxels).sum();
    writeln!(
        out,
        "wrote {} ({} bytes, {} grids, {} active voxels) in {:.2} s",
        args.output.display(),
        bytes,
        grids.len(),
        voxels,
        start.elapsed().as_secs_f64()
    )?;
    Ok(())
}
