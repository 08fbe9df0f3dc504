//! `qbricks-lab bench`: every strategy at several steps against a fine reference.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use files::guard::Guard;
use files::output::QuietStdout;
use lab::bench::{self, BenchOptions, Run};
use viewer::film;
use viewer::mesh::Meshes;
use viewer::render::Renderer;
use viewer::view_state::ViewState;
use viewer::volume::Volume;

/// The default file, relative to the current directory (as `qbricks-view` has it).
const DEFAULT_FILE: &str = "data/wake_small.qbk";

/// `file`, or the bundled sample when there is one in the current directory.
fn resolve_file(file: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    match file {
        Some(f) => Ok(f),
        None => {
            let p = PathBuf::from(DEFAULT_FILE);
            if !p.exists() {
                anyhow::bail!(
                    "{DEFAULT_FILE}: no such file (the default sample is looked up relative to \
                     the current directory; run from the repository root or pass FILE.qbk)"
                );
            }
            Ok(p)
        }
    }
}

/// Opens and validates a `.qbk` file as every render does; `checksum`: verify the payload
/// checksum too.
fn open_volume(path: &std::path::Path, checksum: bool) -> anyhow::Result<format::BrickFileView> {
    let options = viewer::dataset::render_options(checksum);
    format::BrickFileView::open_with(path, &options).map_err(anyhow::Error::from)
}

#[derive(clap::Args)]
pub struct Args {
    /// Brick file [default: data/wake_small.qbk, relative to the current directory].
    pub file: Option<PathBuf>,
    /// View state JSON (camera, mode, iso, spp, …); its strategy and step mark the default run.
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// Print the runs as a JSON list on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Draw RMSE against ms per frame (log axes, one line per strategy) to this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Step of the `uniform` reference, cells.
    #[arg(
        long = "reference-step",
        default_value_t = 0.01,
        allow_hyphen_values = true
    )]
    pub reference_step: f64,
    /// Samples per pixel of the reference [default: the view's, so reference and runs cast
    /// the same camera rays; more measures anti-aliasing as well as sampling].
    #[arg(long = "reference-spp")]
    pub reference_spp: Option<u32>,
    /// Frames per run; `ms` is their median.
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    /// Image size WxH [default: the state's].
    #[arg(long)]
    pub size: Option<String>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let path = resolve_file(args.file.clone())?;
    files::limits::repeat(args.repeat)?;
    files::limits::threads(args.threads)?;
    if let Some(spp) = args.reference_spp {
        files::limits::count("--reference-spp", spp, 1, viewer::view_state::MAX_SPP)?;
    }
    let size = args
        .size
        .as_deref()
        .map(|s| viewer::view_state::parse_size("--size", s, 1))
        .transpose()?;
    let view = open_volume(&path, true)?;
    let vol = Volume::new(&view).with_context(|| format!("{}", path.display()))?;
    let mut state = match &args.state {
        Some(s) => ViewState::load(s)?,
        None => ViewState::default_for_volume(&vol),
    };
    if let Some((w, h)) = size {
        state.width = w;
        state.height = h;
    }
    state
        .validate()
        .map_err(|m| anyhow::anyhow!("view state: {m}"))?;
    let mut guard = Guard::new();
    guard.input("brick file", &path);
    if let Some(s) = &args.state {
        guard.input("--state file", s);
    }
    for m in &state.meshes {
        guard.input("mesh", &m.path);
    }
    if let Some(p) = &args.plot {
        guard.output("--plot", p);
    }
    guard.check()?;
    // The reference and the run being measured are held at once.
    film::check_frame_memory(state.width, state.height, 2)?;
    let meshes = if state.meshes.is_empty() {
        Meshes::empty()
    } else {
        Meshes::load(&state.meshes)?
    };
    let renderer = Renderer::new(args.threads).context("starting worker threads")?;
    let opts = BenchOptions {
        reference_step: args.reference_step,
        reference_spp: args.reference_spp,
        repeat: args.repeat,
        ..BenchOptions::default()
    };
    let total = 1 + bench::plan(&state, &opts).len() as u64;
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(total),
        indicatif::ProgressDrawTarget::stderr(),
    );
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} renders, {elapsed} {msg}")
    {
        bar.set_style(style);
    }
    let (reference, runs) = bench::bench(&renderer, &vol, &state, &meshes, &opts, &mut |what| {
        bar.set_message(what.to_string());
        bar.inc(1);
    })
    .with_context(|| format!("{}", path.display()))?;
    bar.finish_and_clear();
    vol.check_structure(&path)?;
    if let Some(p) = &args.plot {
        let title = format!(
            "{} — {} {}x{}, {} threads",
            path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned()
            ),
            state.mode,
            state.width,
            state.height,
            renderer.threads()
        );
        bench::save_plot(p, &runs, &title)?;
    }
    let mut out = QuietStdout::new();
    if args.json {
        writeln!(out, "{}", serde_json::to_string(&runs)?)?;
    } else {
        writeln!(
            out,
            "{} {}x{}, mode {}, {} threads; reference uniform step {} × {} spp: {:.0} ms",
            path.display(),
            state.width,
            state.height,
            state.mode,
            renderer.threads(),
            opts.reference_step,
            reference.spp,
            reference.ms
        )?;
        write_table(&mut out, &runs)?;
    }
    Ok(())
}

fn write_table(out: &mut impl Write, runs: &[Run]) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<12} {:>5} {:>9} {:>9} {:>8} {:>7} {:>7} {:>7}  pareto",
        "strategy", "step", "ms", "samp/ray", "rmse", "psnr", "miss%", "false%"
    )?;
    for r in runs {
        let psnr = r
            .psnr
            .map_or_else(|| "inf".to_string(), |p| format!("{p:.1}"));
        writeln!(
            out,
            "{:<12} {:>5} {:>9.1} {:>9.1} {:>8.5} {:>7} {:>7.2} {:>7.2}  {}{}",
            if r.preintegrated {
                format!("{}+pre", r.strategy)
            } else {
                r.strategy.to_string()
            },
            r.step,
            r.ms,
            r.samples_per_ray,
            r.rmse,
            psnr,
            100.0 * r.miss_rate,
            100.0 * r.false_hit_rate,
            if r.pareto { "*" } else { "" },
            if r.is_default { " (default)" } else { "" }
        )?;
    }
    Ok(())
}
