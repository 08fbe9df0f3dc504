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

fn parse_size(s: &str) -> anyhow::Result<[f32; 2]> {
    let bad = || anyhow::anyhow!("--size: expected WxH (e.g. 1280x800), found `{s}`");
    let (w, h) = s.split_once('x').ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    if !(64..=16384).contains(&w) || !(64..=16384).contains(&h) {
        return Err(bad());
    }
    Ok([w as f32, h as f32])
}

#[cfg(feature = "gui")]
pub fn run(args: Args) -> anyhow::Result<()> {
    use qbricks_viewer::app::{self, Script, WindowOptions};

    let size = parse_size(&args.size)?;
    if args.threads == Some(0) {
        anyhow::bail!("--threads: expected at least 1, found 0");
    }
    let script = match (args.orbit_frames, &args.screenshot) {
        (Some(0), _) => anyhow::bail!("--orbit-frames: expected at least 1, found 0"),
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
    let _ = parse_size(&args.size)?;
    anyhow::bail!(
        "this qbricks-view was built without the window (cargo feature `gui`); \
         use `qbricks-view render`, `probe` or `info`, or rebuild with default features"
    )
}
