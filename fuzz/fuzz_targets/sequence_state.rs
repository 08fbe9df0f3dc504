//! A frame-sequence manifest, a view state and `qbricks-view render` flags, whatever their
//! bytes, must give a rendered image or an error naming what is wrong, never a panic or a
//! hang: the loaders are the only check between a hand-edited (or damaged) JSON file and
//! the renderer, which trusts what they let through.
//!
//! The input is up to three parts separated by a `0xFF` byte (which UTF-8 text never
//! holds): the manifest (`out_sequence.json` next to the frames; empty: no manifest), the
//! view state (`--state`; absent: no state file) and the flags (whitespace-separated, as
//! on the command line: `--mode dvr --iso 0.2 --frames 1..3 --aov depth …`). The target
//! then does what `qbricks-view render 'out_####.qbk' --state s.json …` does with them
//! (`render_sequence.rs`): it chooses the frames, surveys them with the manifest's field
//! ranges, derives the default state, loads the state file, applies the flags and the
//! field flags, validates, and renders every frame of two small real bakes.
//!
//! The files live in one temporary directory per process, made once with the two frames
//! (the ring-plume scene baked by the library at startup, frames 1 and 3, so frame 2 is a
//! gap) and a small OBJ mesh. Every mesh a state or `--mesh` names is replaced by that
//! mesh, so the fuzzer cannot make the target read other files. Work per input is capped
//! as in `qbk_open`: after validation (which sees the real numbers) images are cut to at
//! most 8×6 pixels and 2 samples per pixel and the step to at least 0.05 cell widths, and
//! at most a few frames are chosen.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use clap::Parser;
use format::sequence::FramePattern;
use libfuzzer_sys::fuzz_target;
use lab::synth::scene_grids_with;
use qbricks_preprocess::bake::{bake, BakeOptions};
use qbricks_preprocess::grid::AnyGrid;
use viewer::dataset::Dataset;
use viewer::mesh::Meshes;
use viewer::render::{render_aov, Aov, Renderer, Scene};
use viewer::sequence::{select_frames, survey, FrameRange};
use viewer::view_state::{Overrides, ViewState};

/// Separates the manifest, the state and the flags.
const SEP: u8 = 0xff;
/// Largest image rendered per frame (the seeds are 8×6).
const MAX_WIDTH: u32 = 8;
const MAX_HEIGHT: u32 = 6;
/// Most samples per pixel rendered.
const MAX_SPP: u32 = 2;
/// Finest step rendered (cell widths): validation allows 1e-3, but at that step a dvr
/// image of 8×6 pixels takes seconds under the sanitizer, which starves the fuzzer; 0.05
/// is still ten times finer than the default.
const MIN_STEP: f64 = 0.05;
/// Most frames chosen per input: `--frames 0..99999` is valid, but opening a hundred
/// thousand missing files per input tells the fuzzer nothing.
const MAX_FRAMES: usize = 8;
/// Frames baked at startup (of the ring-plume scene); the missing ones are gaps.
const FRAMES: [u64; 2] = [1, 3];

/// The flags of `qbricks-view render` that change what is rendered (not where it goes).
#[derive(Parser, Debug)]
#[command(name = "render", no_binary_name = true)]
struct Flags {
    #[arg(long)]
    frames: Option<FrameRange>,
    #[command(flatten)]
    view: Overrides,
    #[arg(long, value_enum)]
    aov: Option<Aov>,
    /// `X,Y`: the pixel's trace as `--pixel` prints it.
    #[arg(long)]
    pixel: Option<String>,
    #[arg(long)]
    no_checksum: bool,
}

/// The per-process directory and what is in it.
struct Setup {
    pattern: FramePattern,
    /// The pattern as given on the command line.
    shown: String,
    manifest: PathBuf,
    state: PathBuf,
    mesh: PathBuf,
    renderer: Renderer,
}

static SETUP: OnceLock<Setup> = OnceLock::new();

/// Makes the directory, bakes the frames and writes the mesh (once per process). A
/// failure here is the harness's, not the code's under test, so it panics.
fn setup() -> Setup {
    const PREFIX: &str = "qbricks-fuzz-sequence-state-";
    let tmp = std::env::temp_dir();
    // libFuzzer ends the process with `exit`, which runs no destructor: remove what
    // earlier runs left instead (directories of processes that are gone, which only
    // Linux's /proc tells).
    let proc_fs = Path::new("/proc/self").exists();
    for entry in std::fs::read_dir(&tmp).into_iter().flatten().flatten() {
        if !proc_fs {
            break;
        }
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some(pid) = name.strip_prefix(PREFIX) {
            if !Path::new("/proc").join(pid).exists() {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
    }
    let dir = tmp.join(format!("{PREFIX}{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    let shown = dir.join("out_####.qbk");
    let pattern = FramePattern::parse(&shown)
        .expect("pattern")
        .expect("placeholder");
    for frame in FRAMES {
        let grids: Vec<AnyGrid> = scene_grids_with("ring-plume", 8, 1, false, frame)
            .expect("synth")
            .into_iter()
            .map(AnyGrid::Vec3s)
            .collect();
        let opts = BakeOptions {
            threads: Some(1),
            ..BakeOptions::default()
        };
        let (file, _) = bake(grids, &opts).expect("bake");
        format::writer::write(&pattern.path(frame), &file).expect("write frame");
    }
    // A tetrahedron around the ring's centre, small enough to leave most rays to the
    // volume.
    let mesh = dir.join("mesh.obj");
    std::fs::write(
        &mesh,
        "v 0.5 0.5 0.6\nv 0.6 0.5 0.4\nv 0.4 0.6 0.4\nv 0.4 0.4 0.4\n\
         f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n",
    )
    .expect("write mesh");
    Setup {
        manifest: pattern.manifest_path(),
        state: dir.join("state.json"),
        pattern,
        shown: shown.display().to_string(),
        mesh,
        renderer: Renderer::new(Some(1)).expect("render thread"),
    }
}

fuzz_target!(|data: &[u8]| {
    let s = SETUP.get_or_init(setup);
    let mut parts = data.splitn(3, |&b| b == SEP);
    let manifest = parts.next().unwrap_or_default();
    let state = parts.next();
    let flags = parts.next().unwrap_or_default();

    let flags = String::from_utf8_lossy(flags);
    // A command line the parser refuses ends the program with its usage.
    let Ok(flags) = Flags::try_parse_from(flags.split_ascii_whitespace()) else {
        return;
    };
    if manifest.is_empty() {
        // No manifest: the ranges come from the frames.
        let _ = std::fs::remove_file(&s.manifest);
    } else {
        std::fs::write(&s.manifest, manifest).expect("write manifest");
    }
    if let Some(state) = state {
        std::fs::write(&s.state, state).expect("write state");
    }
    render(s, state.is_some(), &flags);
});

/// `render_sequence::run`, rendering into memory.
fn render(s: &Setup, from_file: bool, flags: &Flags) {
    let Ok(frames) = select_frames(&s.pattern, &s.shown, flags.frames) else {
        return;
    };
    if frames.len() > MAX_FRAMES {
        return;
    }
    let info = match survey(&s.pattern, &frames) {
        Ok(info) => info,
        Err(e) => {
            assert!(e.to_string().contains("out_sequence.json"), "{e}");
            return;
        }
    };
    // The data-derived view is what a user without a state file gets: a manifest the
    // loader accepts must give one that passes validation.
    let default = info.default_state();
    if let Err(e) = default.validate() {
        panic!("default state of {:?} is invalid: {e}", info.fields);
    }
    let mut state = if from_file {
        match ViewState::load(&s.state) {
            Ok(state) => state,
            Err(e) => {
                assert!(e.to_string().contains("state.json"), "{e}");
                return;
            }
        }
    } else {
        default
    };
    if flags.view.apply(&mut state, from_file).is_err()
        || flags.view.apply_fields(&mut state, &info.fields).is_err()
        || state.validate().is_err()
    {
        return;
    }
    // Only the harness's mesh is ever read.
    for m in &mut state.meshes {
        m.path = s.mesh.clone();
    }
    state.width = state.width.min(MAX_WIDTH);
    state.height = state.height.min(MAX_HEIGHT);
    state.spp = state.spp.min(MAX_SPP);
    state.step = state.step.max(MIN_STEP);
    let meshes = if state.meshes.is_empty() {
        Meshes::empty()
    } else {
        match Meshes::load(&state.meshes) {
            Ok(m) => m,
            Err(e) => panic!("the harness's mesh does not load: {e}"),
        }
    };
    let pixel = flags.pixel.as_deref().and_then(|p| {
        let (x, y) = p.split_once(',')?;
        let (x, y): (u32, u32) = (x.trim().parse().ok()?, y.trim().parse().ok()?);
        (x < state.width && y < state.height).then_some((x, y))
    });
    let options = viewer::dataset::render_options(!flags.no_checksum);
    for (_, input) in &frames {
        if !input.exists() {
            continue;
        }
        let data = match Dataset::open_with(input, &options) {
            Ok(d) => d,
            Err(e) => panic!(
                "{}: a frame the harness baked does not open: {e}",
                input.display()
            ),
        };
        let Ok(scene) = Scene::new(data.volume(), &state, &meshes) else {
            continue;
        };
        if let Some((x, y)) = pixel {
            let _ = s.renderer.trace_pixel(&scene, x, y);
        }
        let frame = match flags.aov {
            Some(aov) => s.renderer.install(|| render_aov(&scene, aov)),
            None => s.renderer.render(&scene),
        };
        assert_eq!(
            frame.rgb.len(),
            state.width as usize * state.height as usize
        );
        let _ = viewer::film::encode_png(frame.width, frame.height, &frame.rgb);
    }
}
