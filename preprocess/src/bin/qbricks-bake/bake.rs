//! `qbricks-bake bake`: argument parsing, progress and output; the work is in
//! `qbricks_preprocess::bake`.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use files::output::QuietStdout;
use indicatif::{HumanDuration, ProgressBar, ProgressStyle};
use qbricks_preprocess::bake::DEFAULT_MAX_BRICK;
use qbricks_preprocess::derive::Stencil;
use qbricks_preprocess::inputs::Layout;
use qbricks_preprocess::progress;
use qbricks_preprocess::request::{bake_one_among, summary_json, BakePlan, BakeRequest};
use ranks::Ranks;

#[derive(clap::Args)]
pub struct Args {
    /// Input OpenVDB file.
    pub input: PathBuf,
    /// Output brick file (default: the input with extension `.qbk`). Written atomically;
    /// never the input itself.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Grid to bake (repeatable; every grid of that name). Default: all vec3 grids, or the
    /// scalar grid when there is no vec3 grid.
    #[arg(long = "grid", value_name = "NAME")]
    pub grids: Vec<String>,
    /// Velocity to bake when the file holds several candidates (repeatable): a vec3 grid
    /// name, or X for three scalar component grids X.x/X.y/X.z, X_x/X_y/X_z or Xx/Xy/Xz.
    #[arg(long, value_name = "NAME")]
    pub velocity: Vec<String>,
    /// Fields, comma separated: q, speed, vorticity (|curl u|), lambda2 (negative in
    /// vortex cores), helicity (u·ω/(|u||ω|)), velocity (three fields velocity_x/y/z), or
    /// the name of any scalar grid of the file (resampled onto the velocity's leaf cells).
    /// Default: q,speed. A scalar grid baked on its own (no velocity) takes no field list.
    #[arg(long, value_delimiter = ',')]
    pub fields: Option<Vec<String>>,
    /// Velocity gradient stencil at grid edges and next to missing cells.
    #[arg(long, value_enum, default_value_t = Stencil::Central)]
    pub stencil: Stencil,
    /// Where velocity components sit: auto (from the grid class), centred or staggered.
    #[arg(long, value_enum, default_value_t = Layout::Auto)]
    pub layout: Layout,
    /// Largest brick edge in cells.
    #[arg(long, default_value_t = DEFAULT_MAX_BRICK)]
    pub max_brick: u32,
    /// Refuse input with non-finite values (default: replace them and warn).
    #[arg(long)]
    pub strict: bool,
    /// Keep the bake within this much memory (64M, 2G, …; default: three quarters of the
    /// machine's): values past a part of it are kept in scratch files beside the output,
    /// and a bake that needs more even so is refused, naming the least that would do. A
    /// sequence shares it between the frames baked at once.
    #[arg(long, value_name = "SIZE", value_parser = memory_arg)]
    pub memory: Option<u64>,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
    /// Print nothing but errors.
    #[arg(long)]
    pub quiet: bool,
    /// For a frame sequence: frames baked at once (default: as many as the threads and the
    /// available memory allow).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Show progress on stderr even when it is not a terminal.
    #[arg(long)]
    pub progress: bool,
}

fn memory_arg(text: &str) -> Result<u64, String> {
    files::limits::memory_size("--memory", text).map_err(|e| e.to_string())
}

/// What the arguments ask for, checked once: the read and bake options, for one file or for
/// every frame of a sequence.
pub struct Plan {
    pub start: Instant,
    pub bake: BakePlan,
}

/// Checks the arguments and builds the options every bake of this run uses.
pub fn plan(args: &Args) -> anyhow::Result<Plan> {
    let request = BakeRequest {
        fields: args.fields.clone(),
        grids: args.grids.clone(),
        velocity: args.velocity.clone(),
        layout: args.layout,
        stencil: args.stencil,
        max_brick: args.max_brick,
        strict: args.strict,
        threads: None,
        memory: args.memory,
    };
    Ok(Plan {
        start: Instant::now(),
        bake: request.plan()?,
    })
}

/// Bakes one file; over the ranks of an MPI run each derives its share of the fields and
/// rank 0 writes the file and reports (see `preprocess::bake::peers`).
pub fn run(args: Args, plan: Plan, ranks: &Ranks) -> anyhow::Result<()> {
    let Plan { start, bake } = plan;
    let input_name = args.input.display().to_string();

    // Progress: on a terminal a bar naming the stage, with the share done and the time
    // left (`preprocess::progress`), shown once the bake has taken a second (short bakes
    // stay silent); with --progress elsewhere, plain stage lines.
    let show = !args.quiet && ranks.is_root() && (args.progress || std::io::stderr().is_terminal());
    let terminal = std::io::stderr().is_terminal();
    let bar: OnceLock<ProgressBar> = OnceLock::new();
    let stage = |name: &str| {
        if !show {
            return;
        }
        if !terminal {
            let t = start.elapsed().as_secs_f64();
            eprintln!("qbricks-bake: {t:7.2} s  {name}");
            return;
        }
        if bar.get().is_none() && start.elapsed() < Duration::from_secs(1) {
            return;
        }
        let b = bar.get_or_init(|| {
            let b = ProgressBar::new(1000).with_elapsed(start.elapsed());
            b.set_style(
                ProgressStyle::with_template("{spinner} {elapsed:>4} [{bar:24}] {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            b.enable_steady_tick(Duration::from_millis(120));
            b
        });
        let done = progress::done_at(name).unwrap_or(0.0);
        b.set_position((done * 1000.0) as u64);
        b.set_message(
            match progress::seconds_left(name, start.elapsed().as_secs_f64()) {
                Some(left) if left < 1.0 => format!("{name}, under a second left"),
                Some(left) => format!(
                    "{name}, about {} left",
                    HumanDuration(Duration::from_secs_f64(left))
                ),
                None => name.to_string(),
            },
        );
    };

    let (output, summary) = bake_one_among(
        &args.input,
        args.output.as_deref(),
        "-o",
        &bake,
        &stage,
        &AtomicBool::new(false),
        ranks,
    )?;
    // The other ranks' part is done: rank 0 writes and reports.
    let Some(summary) = summary else {
        return Ok(());
    };
    if let Some(b) = bar.get() {
        b.finish_and_clear();
    }
    let seconds = start.elapsed().as_secs_f64();

    if !args.quiet {
        for w in &summary.warnings {
            eprintln!("qbricks-bake: warning: {input_name}: {w}");
        }
    }
    let mut out = QuietStdout::new();
    if args.json {
        let mut v = summary_json(&summary, seconds, &output)?;
        if let Some(map) = v.as_object_mut() {
            if let Some(peak) = files::limits::peak_resident() {
                map.insert("peak_memory".to_string(), peak.into());
            }
            // Shared over ranks: how many derived the fields (peak_memory is rank 0's).
            if ranks.is_parallel() {
                map.insert("ranks".to_string(), ranks.size().into());
            }
        }
        writeln!(out, "{}", serde_json::to_string_pretty(&v)?)?;
    } else if !args.quiet {
        writeln!(
            out,
            "{} -> {}: {} input cells, {} leaf cells ({} dropped), {} bricks, {} regions, {} KD nodes, {:.2} s",
            input_name,
            output.display(),
            summary.input_cells,
            summary.leaf_cells,
            summary.dropped_cells,
            summary.bricks,
            summary.regions,
            summary.kd_nodes,
            seconds
        )?;
        for f in &summary.fields {
            writeln!(
                out,
                "  {:<12} min {:>12.6e} max {:>12.6e}",
                f.name, f.min, f.max
            )?;
        }
    }
    Ok(())
}
