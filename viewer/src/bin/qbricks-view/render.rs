//! `qbricks-view render`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use files::guard::Guard;
use files::output::QuietStdout;
use format::sequence::FramePattern;
use qbricks_viewer::film;
use qbricks_viewer::mesh::Meshes;
use qbricks_viewer::overlay;
use qbricks_viewer::overlay::file_title;
use qbricks_viewer::parts;
use qbricks_viewer::render::{visible_range_view, Frame, FrameReport, Renderer, Scene};
use qbricks_viewer::view_state::{Overrides, ResolvedView, ViewState};
use qbricks_viewer::volume::Volume;
use ranks::Ranks;

/// The bundled sample, relative to the current directory.
pub const DEFAULT_FILE: &str = "data/wake_small.qbk";

#[derive(clap::Args)]
pub struct Args {
    /// Brick file to render [default: data/wake_small.qbk, relative to the current
    /// directory], or a frame sequence: 'out/frame_####.qbk' (or %04d) renders every frame
    /// with one view and the sequence's field ranges.
    pub file: Option<PathBuf>,
    /// Output PNG (written atomically). Required unless --pixel is given. For a sequence a
    /// pattern too: 'png/frame_####.png'.
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Sequence: render only frames A..B (both included; also A.., ..B, A). Every number in
    /// the range is expected: a missing file counts as a failed frame.
    #[arg(long)]
    pub frames: Option<qbricks_viewer::sequence::FrameRange>,
    /// Sequence: every frame takes its own default iso value (as if rendered alone: 10 %
    /// of its own maximum of the iso field) instead of the sequence's. Without it only a
    /// frame the sequence's value leaves nearly empty does; either way stderr says which.
    #[arg(long = "iso-per-frame")]
    pub iso_per_frame: bool,
    /// View state JSON to start from (flags override it).
    #[arg(long)]
    pub state: Option<PathBuf>,
    #[command(flatten)]
    pub view: Overrides,
    /// Worker threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the effective view state to this JSON file.
    #[arg(long = "save-state")]
    pub save_state: Option<PathBuf>,
    /// Print timing and statistics as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Render this many times; `ms` is the median.
    #[arg(long, default_value_t = 1)]
    pub repeat: u32,
    /// Write a debug buffer instead of the shaded image: the shading normal, the depth,
    /// the finest contributing level or the colour-field value at the iso-surface.
    #[arg(long, value_enum)]
    pub aov: Option<qbricks_viewer::render::Aov>,
    /// Render only pixel X,Y and print its rays' region segments, samples and hits.
    #[arg(long)]
    pub pixel: Option<String>,
    /// The title line's text, shown with `--overlays …,title` [default: the file's name;
    /// in a sequence, its name and frame number].
    #[arg(long)]
    pub title: Option<String>,
    /// Skip the payload checksum when opening (faster on huge files; the archive is still
    /// validated, so a damaged file is refused, but a flipped value bit would not be).
    #[arg(long)]
    pub no_checksum: bool,
}

/// The file argument, or the bundled sample when it exists.
pub fn resolve_file(file: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    match file {
        Some(f) => Ok(f),
        None => {
            let p = PathBuf::from(DEFAULT_FILE);
            if !p.exists() {
                bail!(
                    "{DEFAULT_FILE}: no such file (the default sample is looked up relative to \
                     the current directory; run from the repository root or pass FILE.qbk)"
                );
            }
            Ok(p)
        }
    }
}

/// Opens and validates a `.qbk` file as every render does
/// ([`qbricks_viewer::dataset::render_options`]); `checksum`: verify the payload checksum
/// too.
pub fn open_volume(path: &Path, checksum: bool) -> anyhow::Result<format::BrickFileView> {
    let options = qbricks_viewer::dataset::render_options(checksum);
    format::BrickFileView::open_with(path, &options).map_err(anyhow::Error::from)
}

/// What `render` is given: the file (the bundled sample by default), or a sequence's frame
/// pattern; the counts checked against the shared bounds first.
pub enum Target {
    File(PathBuf),
    Sequence(PathBuf, FramePattern),
}

/// Resolves the file argument and checks the counts, once for a file or a sequence.
pub fn target(args: &Args) -> anyhow::Result<Target> {
    let path = resolve_file(args.file.clone())?;
    files::limits::repeat(args.repeat)?;
    files::limits::threads(args.threads)?;
    // A path that exists is one file, even with `#` in its name (as in `qbricks-bake`).
    if !path.exists() {
        if let Some(pattern) = FramePattern::parse(&path)? {
            return Ok(Target::Sequence(path, pattern));
        }
    }
    Ok(Target::File(path))
}

/// Renders one file: in one process, or as one frame over the ranks of an MPI run (each
/// rank searching its share of the file's regions, rank 0 compositing and writing; see
/// `qbricks_viewer::parts`). Every step that can fail is agreed between the ranks, so all
/// stop at the same step and rank 0 says why.
pub fn run(args: Args, path: PathBuf, ranks: &Ranks) -> anyhow::Result<()> {
    ranks.agree(check_args(&args, &path, ranks))?;

    // Open. In one process the checksum (it reads every byte) is verified beside the view's
    // set-up and frames, and nothing is written before it matched; over MPI ranks each
    // rank verifies it at open, so that all agree before the frame.
    let beside = !args.no_checksum && !ranks.is_parallel();
    let t_open = Instant::now();
    let view = ranks.agree(open_volume(&path, !args.no_checksum && !beside))?;
    let vol = ranks.agree(Volume::new(&view).with_context(|| format!("{}", path.display())))?;
    let open_ms = t_open.elapsed().as_secs_f64() * 1e3;

    let rendered = qbricks_viewer::dataset::beside_checksum(&view, beside, || {
        render_file(&args, &path, ranks, &vol, open_ms)
    })?;
    let Some(Rendered {
        state,
        trace,
        frame,
        threads,
    }) = rendered
    else {
        return Ok(());
    };
    if let Some(trace) = trace {
        writeln!(
            QuietStdout::new(),
            "{}",
            serde_json::to_string_pretty(&trace)?
        )?;
    }
    let Some((frame, ms, picture)) = frame else {
        return write_outputs(&args, &state, None);
    };
    write_outputs(&args, &state, Some((&frame, picture)))?;
    if args.json {
        let report = FrameReport::new(&frame, &state, ms, open_ms, threads);
        writeln!(QuietStdout::new(), "{}", serde_json::to_string(&report)?)?;
    }
    Ok(())
}

/// What a render of one file in one process writes, made before anything is written.
struct Rendered {
    state: ViewState,
    /// `--pixel`: the pixel's trace.
    trace: Option<qbricks_viewer::render::PixelTrace>,
    /// The frame, its median time (ms) and the picture; `None` for `--pixel` alone.
    frame: Option<(Frame, f64, Vec<u8>)>,
    /// The threads it was rendered on.
    threads: usize,
}

/// The view of `path` and its frames, writing nothing (see [`run`]); over MPI ranks the
/// whole run, which writes on rank 0 (`None`).
fn render_file(
    args: &Args,
    path: &Path,
    ranks: &Ranks,
    vol: &Volume,
    open_ms: f64,
) -> anyhow::Result<Option<Rendered>> {
    // View state: file or data-derived defaults, then flags.
    let resolved = ranks.agree((|| {
        let given = args.state.as_deref().map(ViewState::load).transpose()?;
        let resolved = args.view.resolve(vol, path, given)?;
        check_files(
            args,
            &resolved.state,
            [("brick file".to_string(), path)],
            args.output.iter().map(|o| ("-o".to_string(), o.as_path())),
        )?;
        anyhow::Ok(resolved)
    })())?;
    let ResolvedView {
        mut state,
        notes,
        warnings,
    } = resolved;
    if ranks.is_root() {
        for w in warnings {
            eprintln!("qbricks-view: warning: {}: {w}", path.display());
        }
        for n in notes {
            eprintln!("qbricks-view: note: {n}");
        }
    }
    let meshes = ranks.agree(if state.meshes.is_empty() {
        Ok(Meshes::empty())
    } else {
        Meshes::load(&state.meshes).map_err(anyhow::Error::from)
    })?;
    let renderer = ranks.agree(Renderer::new(args.threads).context("starting worker threads"))?;
    if ranks.is_parallel() {
        run_over_ranks(args, path, ranks, vol, state, &meshes, &renderer, open_ms)?;
        return Ok(None);
    }
    fit_visible(&renderer, vol, &mut state, &meshes, &args.view)
        .with_context(|| path.display().to_string())?;
    let scene = Scene::new(vol, &state, &meshes).with_context(|| format!("{}", path.display()))?;

    // One pixel, explained.
    let trace = match &args.pixel {
        Some(px) => {
            let (x, y) = parse_pixel(px, state.width, state.height)?;
            let trace = renderer.trace_pixel(&scene, x, y);
            vol.check_structure(path)?;
            Some(trace)
        }
        None => None,
    };
    if trace.is_some() && args.output.is_none() {
        drop(scene);
        return Ok(Some(Rendered {
            state,
            trace,
            frame: None,
            threads: renderer.threads(),
        }));
    }

    let (frame, ms) = render_frame(&renderer, &scene, args);
    vol.check_structure(path)?;
    let title = args.title.clone().unwrap_or_else(|| file_title(path));
    let picture = overlay::figure(&frame, &state, vol, args.aov.is_some(), &title);
    drop(scene);
    Ok(Some(Rendered {
        state,
        trace,
        frame: Some((frame, ms, picture)),
        threads: renderer.threads(),
    }))
}

/// What a render of one file is asked that it cannot do, before anything is opened.
fn check_args(args: &Args, path: &Path, ranks: &Ranks) -> anyhow::Result<()> {
    if args.frames.is_some() {
        bail!(
            "{}: --frames needs a frame sequence ('frame_####.qbk' or 'frame_%04d.qbk')",
            path.display()
        );
    }
    if args.iso_per_frame {
        bail!(
            "{}: --iso-per-frame chooses the iso value of each frame of a sequence \
             ('frame_####.qbk'); a single file already takes its own default",
            path.display()
        );
    }
    if args.output.is_none() && args.pixel.is_none() {
        bail!("expected -o OUT.png (or --pixel X,Y)");
    }
    if ranks.is_parallel() {
        let what = match (&args.pixel, &args.aov) {
            (Some(_), _) => Some("--pixel (one ray, explained)"),
            (None, Some(_)) => Some("--aov (debug buffers)"),
            _ => None,
        };
        if let Some(what) = what {
            bail!(
                "{what} runs in one process: over {} MPI ranks one frame renders the shaded \
                 picture; run it without mpirun",
                ranks.size()
            );
        }
    }
    Ok(())
}

/// One frame over the ranks of an MPI run: every rank searches the regions of its share
/// of the file's KD-tree, rank 0 composites, writes the picture and reports (`--json`:
/// the frame, the file's bricks and every rank's time and bricks).
#[allow(clippy::too_many_arguments)]
fn run_over_ranks(
    args: &Args,
    path: &Path,
    ranks: &Ranks,
    vol: &Volume,
    mut state: ViewState,
    meshes: &Meshes,
    renderer: &Renderer,
    open_ms: f64,
) -> anyhow::Result<()> {
    // The regions this rank owns follow from the view (their cost is the iso value's), so
    // they are cut once per scene, not once per frame of `--repeat`.
    let owned_in = |scene: &Scene| -> anyhow::Result<Vec<bool>> {
        ranks.agree(parts::check(scene, ranks.size()).map_err(anyhow::Error::from))?;
        Ok(parts::owned_regions(scene, ranks.rank(), ranks.size()))
    };
    let frame_of = |scene: &Scene,
                    owned: &[bool]|
     -> anyhow::Result<Option<(Frame, Vec<parts::RankReport>)>> {
        let part = parts::render_part(scene, owned, ranks, renderer);
        part.with_context(|| path.display().to_string())
    };
    if args.view.wants_visible_range() {
        // Rank 0 fits its colour map to what a first frame shows; only rank 0 maps colours.
        let first = visible_range_view(&state);
        let scene = ranks
            .agree(Scene::new(vol, &first, meshes).with_context(|| path.display().to_string()))?;
        if let Some((frame, _)) = frame_of(&scene, &owned_in(&scene)?)? {
            if let Some(note) = args
                .view
                .fit_visible_colours_to(&frame, vol, &mut state)
                .with_context(|| path.display().to_string())?
            {
                eprintln!("qbricks-view: note: {note}");
            }
        }
    }
    let scene =
        ranks.agree(Scene::new(vol, &state, meshes).with_context(|| path.display().to_string()))?;
    let owned = owned_in(&scene)?;
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..args.repeat.max(1) {
        let t = Instant::now();
        last = frame_of(&scene, &owned)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    // A part of the file that failed its check on any rank fails the run on every rank.
    ranks.agree(vol.check_structure(path).map_err(anyhow::Error::from))?;
    // The other ranks are done: rank 0 has the frame.
    let Some((frame, reports)) = last else {
        return Ok(());
    };
    times.sort_by(f64::total_cmp);
    let ms = times.get(times.len() / 2).copied().unwrap_or(0.0);
    let title = args.title.clone().unwrap_or_else(|| file_title(path));
    let picture = overlay::figure(&frame, &state, vol, false, &title);
    write_outputs(args, &state, Some((&frame, picture)))?;
    if args.json {
        let report = parts::RanksReport {
            frame: FrameReport::new(&frame, &state, ms, open_ms, renderer.threads()),
            bricks: vol.brick_count(),
            ranks: reports,
        };
        writeln!(QuietStdout::new(), "{}", serde_json::to_string(&report)?)?;
    }
    Ok(())
}

/// Renders the scene `--repeat` times (the shaded image or the `--aov` buffer); returns
/// the last frame and the median wall time in ms.
pub fn render_frame(renderer: &Renderer, scene: &Scene, args: &Args) -> (Frame, f64) {
    let mut times = Vec::new();
    let mut frames = Vec::new();
    for _ in 0..args.repeat.max(1) {
        let t = Instant::now();
        let f = match args.aov {
            Some(aov) => renderer.install(|| qbricks_viewer::render::render_aov(scene, aov)),
            None => renderer.render(scene),
        };
        times.push(t.elapsed().as_secs_f64() * 1e3);
        // Keep only the last frame.
        frames.clear();
        frames.push(f);
    }
    times.sort_by(f64::total_cmp);
    let ms = times.get(times.len() / 2).copied().unwrap_or(0.0);
    match frames.pop() {
        Some(f) => (f, ms),
        // `repeat ≥ 1`, so there is a frame; render once more rather than panic.
        None => (renderer.render(scene), ms),
    }
}

/// Refuses a render whose outputs (the images, `--save-state`) would overwrite one of its
/// inputs (the brick files, the `--state` file, the meshes) or each other, before anything
/// is rendered or written (see `files::guard`).
pub fn check_files<'a>(
    args: &'a Args,
    state: &'a ViewState,
    bricks: impl IntoIterator<Item = (String, &'a Path)>,
    images: impl IntoIterator<Item = (String, &'a Path)>,
) -> Result<(), files::guard::Clash> {
    let mut guard = Guard::new();
    for (role, path) in bricks {
        guard.input(role, path);
    }
    if let Some(s) = &args.state {
        guard.input("--state file", s);
    }
    for m in &state.meshes {
        guard.input("mesh", &m.path);
    }
    for (role, path) in images {
        guard.output(role, path);
    }
    if let Some(s) = &args.save_state {
        guard.output("--save-state", s);
    }
    guard.check()
}

/// Refuses an image too large for the machine (see [`film::check_frame_memory`]).
pub fn check_frame_memory(width: u32, height: u32) -> anyhow::Result<()> {
    Ok(film::check_frame_memory(width, height, 1)?)
}

/// `--colour-range visible` (see [`Overrides::fit_visible_colours`]), its note on stderr.
pub fn fit_visible(
    renderer: &Renderer,
    vol: &Volume,
    state: &mut ViewState,
    meshes: &Meshes,
    view: &Overrides,
) -> anyhow::Result<()> {
    if let Some(note) = view.fit_visible_colours(renderer, vol, state, meshes)? {
        eprintln!("qbricks-view: note: {note}");
    }
    Ok(())
}

/// Writes the PNG (when there is a picture and `-o`) and the `--save-state` file together,
/// only now that the render succeeded, and all or nothing.
fn write_outputs(
    args: &Args,
    state: &ViewState,
    frame: Option<(&Frame, Vec<u8>)>,
) -> anyhow::Result<()> {
    let mut outputs: Vec<(&Path, Vec<u8>)> = Vec::new();
    if let (Some(out), Some((frame, rgb8))) = (&args.output, frame) {
        let png = film::encode_png_rgb8(frame.width, frame.height, rgb8)
            .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
        outputs.push((out, png));
    }
    if let Some(p) = &args.save_state {
        outputs.push((p, format!("{}\n", state.to_json()).into_bytes()));
    }
    let list: Vec<(&Path, &[u8])> = outputs.iter().map(|(p, b)| (*p, b.as_slice())).collect();
    files::output::write_all_atomic(&list)
        .map_err(|(path, e)| anyhow::anyhow!("{}: {e}", path.display()))
}

fn parse_pixel(s: &str, w: u32, h: u32) -> anyhow::Result<(u32, u32)> {
    let bad = || anyhow::anyhow!("--pixel: expected X,Y inside {w}x{h}, found `{s}`");
    let (x, y) = s.split_once(',').ok_or_else(bad)?;
    let x: u32 = x.trim().parse().map_err(|_| bad())?;
    let y: u32 = y.trim().parse().map_err(|_| bad())?;
    if x >= w || y >= h {
        return Err(bad());
    }
    Ok((x, y))
}
