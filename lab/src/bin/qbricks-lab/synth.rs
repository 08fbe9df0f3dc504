//! `qbricks-lab synth`.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use std::io::Write;

use anyhow::Context;
use clap::ValueEnum;
use files::guard::Guard;
use files::input::{read_whole, Limits};
use files::output::QuietStdout;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use lab::synth::{write_scene_with, BoxLayout, SynthOptions, MAX_LAYOUT_BYTES};
use preprocess::sequence::FramePattern;
use preprocess::vdb::write::Compression;

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
    /// Scene: wake (nested boxes), wake-single, lamb-oseen, burgers, abc, ring-plume, or
    /// lamb-oseen-nested, burgers-nested, abc-nested (nested boxes).
    pub scene: String,
    /// Output VDB file (written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Voxels along the longest axis of the coarsest grid.
    #[arg(long, default_value_t = 64)]
    pub n0: u32,
    /// Number of nested levels, each refined by 2 (wake and the -nested scenes; single-grid
    /// scenes ignore it).
    #[arg(long, default_value_t = 3)]
    pub levels: u32,
    /// Sample the scene on the nested boxes of this JSON layout file instead of --n0 and
    /// --levels: {"boxes": [{"cell": W, "min": [x, y, z], "max": [x, y, z]}, …]},
    /// coarsest first, each box halving the cell width and inside the one before
    /// (docs/bench/layouts/ has examples).
    #[arg(long, value_name = "FILE.json", conflicts_with_all = ["n0", "levels"])]
    pub boxes: Option<PathBuf>,
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
    /// Write frames 1..=N of a time-dependent scene (ring-plume); the output must then hold
    /// a frame-number placeholder (out_####.vdb or out_%04d.vdb).
    #[arg(long, value_name = "N")]
    pub frames: Option<u64>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let pattern = FramePattern::parse(&args.output)?;
    let outputs: Vec<(u64, PathBuf)> = match (args.frames, &pattern) {
        (None, None) => vec![(1, args.output.clone())],
        (Some(n), Some(p)) => {
            files::limits::count("--frames", n, 1, files::limits::MAX_FRAMES)?;
            (1..=n).map(|f| (f, p.path(f))).collect()
        }
        (Some(_), None) => anyhow::bail!(
            "{}: --frames needs an output with a frame-number placeholder (e.g. out_####.vdb)",
            args.output.display()
        ),
        (None, Some(_)) => anyhow::bail!(
            "{}: an output with a frame-number placeholder needs --frames N",
            args.output.display()
        ),
    };
    let boxes = match &args.boxes {
        None => None,
        Some(file) => {
            let mut guard = Guard::new();
            guard.input("--boxes file", file);
            for (_, path) in &outputs {
                guard.output("output", path);
            }
            guard.check()?;
            Some(read_layout(file)?)
        }
    };
    let base = SynthOptions {
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
        frame: 1,
        boxes,
    };
    // Checked once, before any frame, so that a refusal names the layout file.
    if let (Some(file), Err(e)) = (&args.boxes, base.check()) {
        return Err(anyhow::Error::new(e).context(format!("{}", file.display())));
    }
    let mut out = QuietStdout::new();
    for (frame, path) in outputs {
        let start = Instant::now();
        let opts = SynthOptions {
            frame,
            ..base.clone()
        };
        // A bar with the time left, on a terminal, once a write takes more than a second.
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden());
        bar.set_style(
            ProgressStyle::with_template(
                "{elapsed:>4} [{bar:30}] {percent:>3}% of {len} leaves, {eta} left",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        let mut shown = false;
        let (grids, bytes) = write_scene_with(&path, &opts, &mut |done, total| {
            bar.set_length(total);
            bar.set_position(done);
            if !shown && start.elapsed() > Duration::from_secs(1) {
                shown = true;
                bar.set_draw_target(ProgressDrawTarget::stderr());
            }
        })
        .with_context(|| format!("synth {}", args.scene))?;
        bar.finish_and_clear();
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
            path.display(),
            bytes,
            grids.len(),
            voxels,
            start.elapsed().as_secs_f64()
        )?;
    }
    Ok(())
}

/// Reads and parses a `--boxes` layout file (checked against the scene when it is sampled).
fn read_layout(file: &std::path::Path) -> anyhow::Result<BoxLayout> {
    let bytes = read_whole(file, Limits::both(MAX_LAYOUT_BYTES))?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not UTF-8 text: {e}", file.display()))?;
    BoxLayout::from_json(text).map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))
}
