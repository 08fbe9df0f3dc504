//! `qbricks-view [FILE]` and `qbricks-view open FILE`: the interactive window.

use std::path::PathBuf;

#[derive(clap::Args, Debug, Default)]
pub struct Args {
    /// Brick file to open [default: data/wake_small.qbk, relative to the current directory].
    pub file: Option<PathBuf>,
    /// View state JSON to start from (as written by "Save view…" or `render --save-state`).
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// Render threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Window size in points, WxH.
    #[arg(long, default_value = "1280x800")]
    pub size: String,
    /// Let the image refine, save a screenshot of the whole window as PNG, and exit.
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    /// With --screenshot: take it after this many frames instead of waiting for the
    /// refined image.
    #[arg(long, requires = "screenshot")]
    pub frames: Option<u32>,
    /// Orbit the camera a full turn over N frames, let the image refine, report the frame
    /// rates and exit (with --screenshot, also save one at the end).
    #[arg(long)]
    pub orbit_frames: Option<u32>,
    /// With --orbit-frames: print the report as one JSON object.
    #[arg(long, requires = "orbit_frames")]
    pub json: bool,
}

/// The window's size in points, `WxH`, each side at least 64 (room for the panel).
fn parse_size(s: &str) -> anyhow::Result<[f32; 2]> {
    let (w, h) = qbricks_viewer::view_state::parse_size("--size", s, 64)?;
    Ok([w as f32, h as f32])
}

/// Checks every count and size argument against the shared bounds, and the screenshot
/// against the files the window reads, before the window opens.
fn check(args: &Args) -> anyhow::Result<[f32; 2]> {
    use files::limits;
    let size = parse_size(&args.size)?;
    limits::threads(args.threads)?;
    if let Some(n) = args.orbit_frames {
        limits::count("--orbit-frames", n, 1, limits::MAX_ORBIT_FRAMES)?;
    }
    if let Some(n) = args.frames {
        limits::count("--frames", n, 1, limits::MAX_ORBIT_FRAMES)?;
    }
    // The progressive renderer keeps the image being refined, the one on screen and the
    // texture: three frames at the window's size (at one pixel per point; the panel
    // takes part of it).
    qbricks_viewer::film::check_frame_memory(size[0] as u32, size[1] as u32, 3)?;
    if let Some(shot) = &args.screenshot {
        let mut guard = files::guard::Guard::new();
        let file = args
            .file
            .clone()
            .unwrap_or_else(|| PathBuf::from(crate::render::DEFAULT_FILE));
        guard.input("brick file", &file);
        if let Ok(Some(pattern)) = format::sequence::FramePattern::parse(&file) {
            for (f, p) in pattern.scan().unwrap_or_default() {
                guard.input(format!("frame {f}"), &p);
            }
            let manifest = pattern.manifest_path();
            if manifest.exists() {
                guard.input("manifest", &manifest);
            }
        }
        if let Some(s) = &args.state {
            guard.input("--state file", s);
            // Its meshes, when it reads; a state that does not is reported by the window.
            if let Ok(state) = qbricks_viewer::view_state::ViewState::load(s) {
                for m in &state.meshes {
                    guard.input("mesh", &m.path);
                }
            }
        }
        guard.output("--screenshot", shot);
        guard.check()?;
    }
    Ok(size)
}

#[cfg(feature = "gui")]
pub fn run(args: Args) -> anyhow::Result<()> {
    use qbricks_viewer::app::{self, Script, WindowOptions};

    let size = check(&args)?;
    let script = match (args.orbit_frames, &args.screenshot) {
        (Some(frames), shot) => Some(Script::Orbit {
            frames,
            screenshot: shot.clone(),
        }),
        (None, Some(out)) => Some(Script::Screenshot {
            out: out.clone(),
            frames: args.frames,
        }),
        (None, None) => None,
    };
    let report = app::run(WindowOptions {
        file: args.file,
        state: args.state,
        threads: args.threads,
        size,
        script,
    })?;
    if let (Some(r), true) = (report, args.json) {
        use std::io::Write;
        writeln!(
            files::output::QuietStdout::new(),
            "{}",
            serde_json::to_string(&r)?
        )?;
    }
    Ok(())
}

#[cfg(not(feature = "gui"))]
pub fn run(args: Args) -> anyhow::Result<()> {
    check(&args)?;
    anyhow::bail!(
        "this qbricks-view was built without the window (cargo feature `gui`); \
         use `qbricks-view render`, `probe` or `info`, or rebuild with default features"
    )
}
