//! The window: its parts by concern (the open data, the view, the images, the dialogs,
//! picking), the one place that handles what the panel asks for, and a frame of the UI.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use eframe::egui;
use format::sequence::FramePattern;

use super::background::{self, Poll};
use super::canvas::{self, Canvas};
use super::command::{AppCommand, Cut};
use super::dialogs::{self, DialogPurpose, Dialogs};
use super::document::{self, Doc, Document, Opening, DEFAULT_FILE};
use super::frames::Frames;
use super::framing::{self, Fit, Purpose};
use super::help;
use super::history::{History, Snapshot};
use super::keys::{self, KeyAction};
use super::menu::{self, MenuState};
use super::navigation;
use super::options::WindowOptions;
use super::panel::{self, Panel};
use super::picking::Picking;
use super::player::Player;
use super::script::{OrbitReport, ScriptRunner, ScriptStep};
use super::status::status_text;
use super::view::{self, ViewControls};
use crate::film;
use crate::mesh::MeshInstance;
use crate::planes::{Plane, Slice, MAX_CLIP_PLANES, MAX_SLICES};
use crate::progressive::Progressive;
use crate::view_state::{FieldRange, ViewCommand, ViewState};

/// How often the window looks at work on its way while nothing else redraws it.
const BACKGROUND_POLL: std::time::Duration = std::time::Duration::from_millis(50);

/// Samples per pixel the window refines to when the view state does not say.
const WINDOW_SPP: u32 = 4;

/// What a scripted run ends with: its report, or why it failed.
type Outcome = Arc<Mutex<Option<anyhow::Result<Option<OrbitReport>>>>>;

/// The window.
pub struct ViewerApp {
    /// The view being shown. The panel edits its plain settings in place and asks for
    /// the changes that follow a rule (an `AppCommand`, handled in `ViewerApp::handle`).
    pub state: ViewState,
    /// Point the camera orbits around.
    pub pivot: [f64; 3],
    /// Render resolution relative to the window's pixels.
    pub resolution_scale: f32,
    /// Generation of the job the renderer is working on.
    pub generation: u64,
    /// One-line message shown at the top of the panel (bad file, failed save, …).
    pub error: Option<String>,
    /// The frames when the window was opened on a sequence pattern (`frame_####.qbk`).
    pub sequence: Option<Player>,
    /// The open file, the field ranges the view's rules use, the state file loaded.
    pub(crate) document: Document,
    /// The window's own view settings (the light rig, switched-off meshes).
    pub(crate) controls: ViewControls,
    /// The renderer and the images it sent.
    pub(crate) frames: Frames,
    pub(crate) dialogs: Dialogs,
    pub(crate) picking: Picking,
    /// The views before and after the one shown (undo, redo).
    pub(crate) history: History,
    /// The list of keys and mouse bindings is shown.
    pub(crate) help_open: bool,
    /// Generation of the first job of the sequence frame shown, so playback knows when
    /// that frame is on screen (`None`: not submitted yet).
    frame_job: Option<u64>,
    /// Image size in pixels the central area asks for.
    viewport_px: [u32; 2],
    script: Option<ScriptRunner>,
    outcome: Outcome,
    /// The error of opening the file or the state the window was started with.
    startup_error: Option<String>,
    last_ui: Option<Instant>,
    /// A file being opened, off the UI thread.
    opening: Option<Opening>,
    /// The camera fit to the surface on its way (a file's first view, or F).
    framing: Option<Fit>,
    /// How long the UI thread waits for an open or a fit before leaving it to arrive
    /// later ([`background::WAIT`]).
    pub(crate) background_wait: std::time::Duration,
    /// When the window was made, and then its first UI frame and the first framed view
    /// (ms after it), for the script's report.
    created: Instant,
    first_ui_ms: Option<f64>,
    framed_ms: Option<f64>,
}

impl ViewerApp {
    /// A window on `options.file` (or the bundled sample). A file that fails to open is
    /// reported in the window, not as an error: the window still opens.
    pub(crate) fn new(
        ctx: egui::Context,
        options: WindowOptions,
        outcome: Outcome,
    ) -> anyhow::Result<ViewerApp> {
        let created = Instant::now();
        let placeholder = [FieldRange {
            name: "q".into(),
            min: 0.0,
            max: 1.0,
        }];
        let mut app = ViewerApp {
            state: ViewState::default_for([0.0; 3], [1.0; 3], &placeholder),
            pivot: [0.0; 3],
            resolution_scale: 1.0,
            generation: 0,
            error: None,
            sequence: None,
            document: Document::default(),
            controls: ViewControls::default(),
            frames: Frames::new(options.threads, ctx)?,
            dialogs: Dialogs::new(),
            picking: Picking::default(),
            history: History::default(),
            help_open: false,
            frame_job: None,
            viewport_px: [0, 0],
            script: options.script.map(ScriptRunner::new),
            outcome,
            startup_error: None,
            last_ui: None,
            opening: None,
            framing: None,
            background_wait: background::WAIT,
            created,
            first_ui_ms: None,
            framed_ms: None,
        };
        let file = options
            .file
            .clone()
            .unwrap_or_else(|| PathBuf::from(DEFAULT_FILE));
        app.open_file(&file);
        match app.opening.as_mut() {
            Some(o) => {
                o.startup = true;
                o.state = options.state.clone();
            }
            None => app.after_startup_open(options.state.as_deref()),
        }
        Ok(app)
    }

    /// Once the window's first file is open (or failed to): loads the `--state` file,
    /// and the view it starts with becomes the oldest step.
    fn after_startup_open(&mut self, state: Option<&Path>) {
        if let Some(s) = state {
            self.load_state(s);
        }
        self.startup_error = self.error.clone();
        self.history.reset(self.snapshot());
    }

    /// A window for tests: no script, no eframe, repaints requested on `ctx` once the
    /// harness shows it.
    pub fn for_tests(file: &Path, threads: Option<usize>) -> anyhow::Result<ViewerApp> {
        let options = WindowOptions {
            file: Some(file.to_path_buf()),
            threads,
            size: [1000.0, 700.0],
            ..WindowOptions::default()
        };
        let mut app = Self::new(egui::Context::default(), options, Arc::default())?;
        app.frames.repaint = Arc::new(OnceLock::new());
        Ok(app)
    }

    pub fn renderer(&self) -> &Progressive {
        self.frames.renderer()
    }

    /// Path of the open file.
    pub fn file(&self) -> Option<&Path> {
        self.document.doc.as_ref().map(|d| d.path.as_path())
    }

    /// Opens `path`, or the sequence when it is a frame pattern (`frame_####.qbk`) that is
    /// not itself a file; on failure the error is shown and the current file stays open.
    pub(crate) fn open_file(&mut self, path: &Path) {
        if let Some(hint) = document::bake_hint(path) {
            self.error = Some(hint);
            return;
        }
        if !path.exists() {
            match FramePattern::parse(path) {
                Ok(Some(pattern)) => return self.open_sequence(path, &pattern),
                Ok(None) => {}
                Err(e) => {
                    self.error = Some(e.to_string());
                    return;
                }
            }
        }
        // Another file asked for replaces one on its way.
        let opening = Opening::start(path);
        match opening.job.wait(self.background_wait) {
            Poll::Pending => self.opening = Some(opening),
            outcome => self.take_open(opening, outcome),
        }
    }

    /// Shows the file opened (or the error) of `opening`.
    fn take_open(&mut self, opening: Opening, outcome: Poll<Result<Doc, String>>) {
        self.opening = None;
        let opened = match outcome {
            Poll::Done(opened) => opened,
            Poll::Failed => Err(format!("{}: opening failed", opening.path.display())),
            Poll::Pending => return,
        };
        match (opened, opening.frame) {
            (opened, true) => self.show_frame_doc(opened),
            (Ok(doc), false) => self.show_doc(doc),
            (Err(e), false) => self.error = Some(e),
        }
        if opening.startup {
            self.after_startup_open(opening.state.as_deref());
        }
    }

    /// Shows a newly opened file in its default view: the camera on the whole data until
    /// the fit to the surface arrives (`ViewState::default_for_volume`, off the UI thread).
    fn show_doc(&mut self, doc: Doc) {
        let vol = doc.dataset.volume();
        let state = ViewState::default_unframed(vol);
        self.document.ranges = vol.fields.clone();
        let fit = Fit::start(Arc::clone(&doc.dataset), &state, Purpose::Open);
        self.start_view(state);
        self.document.doc = Some(doc);
        self.frames.finished = None;
        self.picking.forget();
        self.sequence = None;
        self.history.reset(self.snapshot());
        self.await_fit(fit);
    }

    /// Applies the fit if it arrives within [`Self::background_wait`], else leaves it to
    /// [`Self::poll_background`].
    fn await_fit(&mut self, fit: Fit) {
        match fit.job.wait(self.background_wait) {
            Poll::Pending => self.framing = Some(fit),
            outcome => self.take_fit(&fit, outcome),
        }
    }

    /// Applies a finished fit when it still fits the view shown ([`Fit::applies`]).
    fn take_fit(&mut self, fit: &Fit, outcome: framing::Outcome) {
        self.framing = None;
        let camera = match outcome {
            Poll::Done(camera) => camera,
            Poll::Failed => {
                self.error = Some("Frame surface: the camera fit failed".to_string());
                return;
            }
            Poll::Pending => return,
        };
        let dataset = self.document.doc.as_ref().map(|d| &d.dataset);
        if !fit.applies(dataset, &self.state) {
            return;
        }
        self.state.camera = camera;
        self.state.lights_follow_camera();
        self.pivot = camera.look_at;
        match fit.purpose {
            // As the file's first view, which nothing can undo back to.
            Purpose::Open => {
                if !self.history.can_undo() {
                    self.history.reset(self.snapshot());
                }
            }
            Purpose::Asked => self.controls.relight(&mut self.state),
        }
    }

    /// Takes the file being opened and the camera fit on their way if they are done;
    /// asks for another UI frame while they are not.
    pub(crate) fn poll_background(&mut self, ctx: &egui::Context) {
        // The fit first: one that an open taken here starts is looked at next frame.
        if let Some(fit) = self.framing.take() {
            match fit.job.poll() {
                Poll::Pending => self.framing = Some(fit),
                outcome => self.take_fit(&fit, outcome),
            }
        }
        if let Some(opening) = self.opening.take() {
            match opening.job.poll() {
                Poll::Pending => self.opening = Some(opening),
                outcome => self.take_open(opening, outcome),
            }
        }
        let framing = self.background_pending();
        let checksum_pending = self.document.doc.as_mut().is_some_and(|doc| {
            if !framing {
                doc.checksum.start(&doc.dataset);
            }
            doc.checksum.poll();
            doc.checksum_pending()
        });
        if self.background_pending() || checksum_pending {
            // Often enough to take the result soon after it comes; seldom enough that
            // drawing the window (a software renderer's full repaint) takes little
            // from the work. Input repaints at once anyway.
            ctx.request_repaint_after(BACKGROUND_POLL);
        }
    }

    /// Whether a file is being opened or the camera fitted.
    pub(crate) fn background_pending(&self) -> bool {
        self.opening.is_some() || self.framing.is_some()
    }

    /// Whether a file is being opened.
    #[cfg(test)]
    pub(crate) fn opening_pending(&self) -> bool {
        self.opening.is_some()
    }

    /// Whether the sequence's current frame counts as shown (an image of it, or its
    /// error, is on screen), so that playback may step on.
    #[cfg(test)]
    pub(crate) fn frame_shown(&self) -> bool {
        self.frame_on_screen()
    }

    /// What the window is busy with beside rendering, for the status line.
    pub(crate) fn busy(&self) -> Option<String> {
        match (&self.opening, &self.framing) {
            (Some(o), _) => Some(format!("opening {}…", o.path.display())),
            (None, Some(_)) => Some("framing the surface…".to_string()),
            (None, None) => None,
        }
    }

    /// Opens a frame sequence: one view state for every frame, derived from what the
    /// frames share (the union of their boxes, the manifest's field ranges) as `render`
    /// does, so frames can be compared by colour; then the first frame.
    fn open_sequence(&mut self, path: &Path, pattern: &FramePattern) {
        let shown = path.display().to_string();
        let plan = match crate::sequence::plan(pattern, &shown, None) {
            Ok(p) => p,
            Err(e) => {
                self.error = Some(e.to_string());
                return;
            }
        };
        let (frames, info) = (plan.frames, plan.info);
        // A file still opening, or its camera still fitted, would replace the sequence.
        self.opening = None;
        self.framing = None;
        self.start_view(info.default_state());
        self.document.ranges = info.fields;
        self.controls.lights_follow = true;
        self.sequence = Some(Player::new(shown, frames));
        self.document.doc = None;
        self.show_frame();
        self.history.reset(self.snapshot());
    }

    /// Shows `state` (the defaults of newly opened data) at the window's size and
    /// samples per pixel.
    fn start_view(&mut self, mut state: ViewState) {
        state.spp = WINDOW_SPP;
        state.width = self.state.width;
        state.height = self.state.height;
        self.pivot = state.camera.look_at;
        self.state = state;
        self.error = None;
    }

    /// Opens the player's current frame, keeping the view. A frame that fails shows its
    /// error and leaves the last good frame on screen; playback goes on past it.
    pub(crate) fn show_frame(&mut self) {
        let Some(path) = self
            .sequence
            .as_ref()
            .and_then(|p| p.path().map(Path::to_path_buf))
        else {
            return;
        };
        self.picking.forget();
        self.frames.finished = None;
        // Not on screen until it is open and rendered: playback waits for it.
        self.frame_job = None;
        let opening = Opening::start_frame(&path);
        match opening.job.wait(self.background_wait) {
            Poll::Pending => self.opening = Some(opening),
            outcome => self.take_open(opening, outcome),
        }
    }

    /// Shows a sequence's frame opened (or its error), keeping the view.
    fn show_frame_doc(&mut self, opened: Result<Doc, String>) {
        match opened {
            Ok(doc) => {
                self.document.doc = Some(doc);
                self.error = None;
                // The view did not change, the data did: render again.
                self.frames.data_changed();
                self.frame_job = None;
            }
            Err(e) => {
                self.error = Some(e);
                // Counts as shown, so playback does not stall on it.
                self.frame_job = Some(0);
            }
        }
    }

    /// Whether an image of the current frame is on screen (a preview counts).
    fn frame_on_screen(&self) -> bool {
        match (self.frame_job, &self.frames.shown) {
            (Some(0), _) => true,
            (Some(g), Some(s)) => s.update.generation >= g,
            _ => false,
        }
    }

    /// Loads a view state file; it must name fields of the open data (the same lookup,
    /// and the same error, as `render --state`).
    pub fn load_state(&mut self, path: &Path) {
        let loaded = ViewState::load(path)
            .map_err(|e| e.to_string())
            .and_then(|s| {
                if self.document.doc.is_none() {
                    return Err("no file is open".to_string());
                }
                let ranges = &self.document.ranges;
                for (key, name) in [
                    ("iso_field", &s.iso_field),
                    ("colormap.field", &s.colormap.field),
                ] {
                    crate::fields::find(ranges, name)
                        .map_err(|e| format!("{}: {}", path.display(), e.named_by(key)))?;
                }
                Ok(s)
            });
        match loaded {
            Ok(s) => {
                // The loaded camera is the user's: no fit made before replaces it.
                self.framing = None;
                self.pivot = s.camera.look_at;
                // The loaded lights are the user's: keep them where they are.
                self.controls.lights_follow = false;
                self.state = s;
                self.document.state_file = Some(path.to_path_buf());
                self.error = None;
                // The values picked belong to the old view's surface.
                self.picking.pick = None;
            }
            Err(m) => self.error = Some(m),
        }
    }

    /// Refuses to save over a file the window reads (see [`Document::check_output`]).
    fn check_output(&self, role: &str, path: &Path) -> Result<(), String> {
        let meshes = self.state.meshes.iter().chain(&self.controls.hidden_meshes);
        self.document
            .check_output(self.sequence.as_ref(), meshes, role, path)
    }

    /// Writes the view state (the same JSON `render --state` reads), adding `.json` to a
    /// name without it.
    pub fn save_state(&mut self, path: &Path) {
        let path = &dialogs::with_extension(path, "json");
        let result = self
            .check_output("Save view", path)
            .and_then(|()| self.state.save(path).map_err(|e| e.to_string()));
        if let Err(m) = result {
            self.error = Some(m);
        }
    }

    /// Writes the finished full-resolution image as a PNG, adding `.png` to a name
    /// without it.
    pub fn save_png(&mut self, path: &Path) {
        let path = &dialogs::with_extension(path, "png");
        let doc = self.document.doc.as_ref();
        let result = match &self.frames.finished {
            _ if doc.is_some_and(Doc::checksum_pending) => Err(format!(
                "{}: the file's checksum is still being verified; save once it is",
                path.display()
            )),
            _ if let Some(e) = doc.and_then(Doc::failure) => Err(e),
            Some(u) => self.check_output("Save image", path).and_then(|()| {
                let (w, h, rgb8) = u.picture();
                film::save_png_rgb8(path, w, h, rgb8).map_err(|e| e.to_string())
            }),
            None => Err(format!(
                "{}: the image is still rendering; save it once it is finished",
                path.display()
            )),
        };
        if let Err(m) = result {
            self.error = Some(m);
        }
    }

    /// Does what the panel (or a key) asked for: the one place where the window changes
    /// its view by a rule. View changes go through [`ViewState::apply`] with the data's
    /// field ranges, as the command line's flags do.
    pub(crate) fn handle(&mut self, command: AppCommand) {
        match command {
            AppCommand::View(c) => {
                if let Err(e) = self.state.apply(&c, &self.document.ranges) {
                    self.error = Some(e.to_string());
                }
            }
            AppCommand::FitColoursToVisible => {
                let range = self
                    .frames
                    .finished
                    .as_ref()
                    .and_then(|u| u.surface.as_ref())
                    .and_then(|s| crate::colormap::visible_range(&s.1));
                match range {
                    Some(r) => {
                        let command = ViewCommand::ColourScale {
                            palette: self.controls.palette,
                            range: Some(r),
                            centre: None,
                            log: self.controls.log,
                        };
                        if let Err(e) = self.state.apply(&command, &self.document.ranges) {
                            self.error = Some(e.to_string());
                        }
                    }
                    None => {
                        self.error =
                            Some("Fit to visible: no surface in the finished picture".to_string())
                    }
                }
            }
            AppCommand::FrameData => {
                if let Some(doc) = &self.document.doc {
                    let vol = doc.dataset.volume();
                    let (min, max) = (vol.to_world(vol.bounds_min), vol.to_world(vol.bounds_max));
                    self.pivot = view::frame_box(&mut self.state, min, max);
                }
                self.controls.relight(&mut self.state);
            }
            AppCommand::FrameSurface => match &self.document.doc {
                Some(doc) => {
                    let fit = Fit::start(Arc::clone(&doc.dataset), &self.state, Purpose::Asked);
                    self.await_fit(fit);
                }
                None => self.controls.relight(&mut self.state),
            },
            AppCommand::Relight => self.controls.relight(&mut self.state),
            AppCommand::Dialog(purpose) => {
                let open = self.document.doc.as_ref().map(|d| d.path.clone());
                self.dialogs.open(purpose, open.as_deref());
            }
            AppCommand::ShowFrame => self.show_frame(),
            AppCommand::AddMesh => match MeshInstance::parse(self.controls.mesh_spec.trim()) {
                Ok(m) => {
                    self.state.meshes.push(m);
                    self.controls.mesh_spec.clear();
                }
                Err(e) => self.error = Some(format!("mesh: {e}")),
            },
            AppCommand::RemoveMesh(i) if i < self.state.meshes.len() => {
                self.state.meshes.remove(i);
            }
            AppCommand::HideMesh(i) if i < self.state.meshes.len() => {
                let m = self.state.meshes.remove(i);
                self.controls.hidden_meshes.push(m);
            }
            AppCommand::ShowMesh(i) if i < self.controls.hidden_meshes.len() => {
                let m = self.controls.hidden_meshes.remove(i);
                self.state.meshes.push(m);
            }
            AppCommand::RemoveMesh(_) | AppCommand::HideMesh(_) | AppCommand::ShowMesh(_) => {}
            AppCommand::AddSurface => {
                self.state.add_surface();
            }
            AppCommand::RemoveSurface(i) => {
                self.state.remove_surface(i);
            }
            AppCommand::AddPlane(cut) => self.add_plane(cut),
            AppCommand::RemovePlane(Cut::Clip, i) if i < self.state.clip.len() => {
                self.state.clip.remove(i);
            }
            AppCommand::RemovePlane(Cut::Slice, i) if i < self.state.slices.len() => {
                self.state.slices.remove(i);
            }
            AppCommand::RemovePlane(..) => {}
            AppCommand::Undo => {
                let back = self.history.undo(&self.snapshot());
                self.restore(back);
            }
            AppCommand::Redo => {
                let forward = self.history.redo(&self.snapshot());
                self.restore(forward);
            }
            AppCommand::Help => self.help_open = !self.help_open,
        }
    }

    /// Adds a clip plane or slice (up to the library's limits) through the pivot, or the
    /// point of the data's box nearest it, across the axis the view looks along most.
    fn add_plane(&mut self, cut: Cut) {
        let Some(doc) = &self.document.doc else {
            return;
        };
        let (lo, hi) = crate::overlay::data_bounds(doc.dataset.volume());
        let at: [f64; 3] = std::array::from_fn(|a| self.pivot[a].max(lo[a]).min(hi[a]));
        let cam = &self.state.camera;
        let forward: [f64; 3] = std::array::from_fn(|a| cam.look_at[a] - cam.eye[a]);
        let plane = Plane::facing_view(at, forward);
        match cut {
            Cut::Clip if self.state.clip.len() < MAX_CLIP_PLANES => self.state.clip.push(plane),
            Cut::Slice if self.state.slices.len() < MAX_SLICES => {
                self.state.slices.push(Slice::new(plane));
            }
            Cut::Clip | Cut::Slice => {}
        }
    }

    /// The view as the history records it.
    fn snapshot(&self) -> Snapshot {
        Snapshot {
            state: self.state.clone(),
            pivot: self.pivot,
            hidden_meshes: self.controls.hidden_meshes.clone(),
        }
    }

    /// Shows a view of the history, at the window's current image size.
    fn restore(&mut self, snapshot: Option<Snapshot>) {
        let Some(s) = snapshot else {
            return;
        };
        // A view of the history replaces the one a fit on its way was made for.
        self.framing = None;
        let (width, height) = (self.state.width, self.state.height);
        self.state = s.state;
        self.state.width = width;
        self.state.height = height;
        self.pivot = s.pivot;
        self.controls.hidden_meshes = s.hidden_meshes;
    }

    /// Does what this frame's keys ask for ([`keys::KEYS`]).
    fn take_keys(&mut self, ctx: &egui::Context) {
        for action in keys::pressed(ctx, self.help_open) {
            match action {
                KeyAction::FrameData => self.handle(AppCommand::FrameData),
                KeyAction::FrameSurface => self.handle(AppCommand::FrameSurface),
                KeyAction::Undo => self.handle(AppCommand::Undo),
                KeyAction::Redo => self.handle(AppCommand::Redo),
                KeyAction::Help => self.handle(AppCommand::Help),
                KeyAction::CloseHelp => self.help_open = false,
            }
        }
    }

    /// The menu bar; what was chosen in it is handled once it is drawn.
    fn menu(&mut self, ui: &mut egui::Ui) {
        let st = &self.state;
        let has_data = self.document.doc.is_some();
        let m = MenuState {
            can_undo: self.history.can_undo(),
            can_redo: self.history.can_redo(),
            has_data,
            can_add_surface: st.mode == crate::transfer::Mode::Iso
                && st.surfaces().len() < crate::view_state::MAX_ISO_SURFACES,
            can_add_clip: has_data && st.clip.len() < MAX_CLIP_PLANES,
            can_add_slice: has_data && st.slices.len() < MAX_SLICES,
        };
        for c in menu::show(&m, ui) {
            self.handle(c);
        }
    }

    /// Opens a file by its kind (extension): a `.json` is a view state, an `.obj` a
    /// mesh, anything else a brick file.
    pub fn open_any(&mut self, path: &Path) {
        match path.extension().and_then(|e| e.to_str()) {
            Some("json") => self.load_state(path),
            Some("obj") => self
                .state
                .meshes
                .push(MeshInstance::at_origin(path.to_path_buf())),
            _ => self.open_file(path),
        }
    }

    /// Opens the files dropped on the window.
    fn take_dropped(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .collect()
        });
        for path in dropped {
            self.open_any(&path);
        }
    }

    /// Acts on the file picked in the dialog this frame.
    fn handle_dialog(&mut self, ctx: &egui::Context) {
        let Some((purpose, path)) = self.dialogs.update(ctx) else {
            return;
        };
        match purpose {
            DialogPurpose::OpenFile => self.open_file(&path),
            DialogPurpose::SavePng => self.save_png(&path),
            DialogPurpose::SaveState => self.save_state(&path),
            DialogPurpose::LoadState => self.load_state(&path),
            DialogPurpose::AddMesh => {
                self.controls.mesh_spec = path.display().to_string();
                self.handle(AppCommand::AddMesh);
            }
        }
    }

    /// The side panel; what it asked for is handled once it is drawn.
    fn panel(&mut self, ui: &mut egui::Ui) {
        let commands = panel::show(
            Panel {
                error: self.error.as_deref(),
                doc: self.document.doc.as_ref(),
                player: self.sequence.as_mut(),
                state: &mut self.state,
                controls: &mut self.controls,
                picking: &mut self.picking.on,
                resolution_scale: &mut self.resolution_scale,
            },
            ui,
        );
        for c in commands {
            self.handle(c);
        }
    }

    /// The central image and its navigation.
    fn central(&mut self, ui: &mut egui::Ui) {
        let moved = canvas::show(
            Canvas {
                state: &mut self.state,
                pivot: &mut self.pivot,
                viewport_px: &mut self.viewport_px,
                resolution_scale: self.resolution_scale,
                shown: self.frames.shown.as_ref(),
                doc: self.document.doc.as_ref(),
                meshes: &self.frames.meshes,
                picking: &mut self.picking,
            },
            ui,
        );
        if moved {
            self.handle(AppCommand::Relight);
        }
    }

    /// Hands the view to the renderer if it changed since the last job. Not while a newly
    /// opened file's camera is being fitted: a picture of the whole data would take the
    /// cores (and the disk) from the fit, and the framed view would come later.
    fn submit_if_changed(&mut self) {
        if self
            .framing
            .as_ref()
            .is_some_and(|f| f.purpose == Purpose::Open)
        {
            return;
        }
        let Some(doc) = &self.document.doc else {
            return;
        };
        if doc.failure().is_some() {
            // Refused (its error is shown): nothing more is rendered of it.
            return;
        }
        let dataset = Arc::clone(&doc.dataset);
        if let Some(g) = self
            .frames
            .submit_if_changed(&dataset, &mut self.state, &mut self.error)
        {
            self.generation = g;
        }
    }

    /// One frame of the window (also what the UI tests drive).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let ctx = ui.ctx().clone();
        let _ = self.frames.repaint.set(ctx.clone());
        let now = Instant::now();
        let frame_interval = self.last_ui.map(|t| now.duration_since(t));
        self.last_ui = Some(now);
        let created = self.created;
        let since_created = || now.duration_since(created).as_secs_f64() * 1e3;
        self.first_ui_ms.get_or_insert_with(since_created);
        self.poll_background(&ctx);

        // A scripted run (`--screenshot`, `--orbit-frames`) whose file or state failed to
        // open has nothing to show: it fails with that error and writes nothing, as
        // `render` would.
        if let (Some(_), Some(e)) = (&self.script, &self.startup_error) {
            if let Ok(mut g) = self.outcome.lock() {
                *g = Some(Err(anyhow::anyhow!("{e}")));
            }
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        // A script starts once the camera frames the surface (its pictures are of that view).
        let framed = !self.background_pending();
        if framed {
            self.framed_ms.get_or_insert_with(since_created);
        }
        if let Some(script) = self.script.as_mut().filter(|_| framed) {
            if let ScriptStep::Orbit(yaw) = script.before_frame(frame_interval) {
                navigation::orbit(&mut self.state.camera, self.pivot, yaw, 0.0);
                self.handle(AppCommand::Relight);
            }
        }
        self.take_dropped(&ctx);
        self.take_keys(&ctx);

        egui::Panel::top("menu").show(ui, |ui| self.menu(ui));
        egui::Panel::left("controls")
            .resizable(true)
            .default_size(300.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.panel(ui));
            });
        // One line of fixed height: a status text that wrapped to two lines would shrink
        // the image, which changes the render size, which starts a new frame, whose
        // status text is shorter again, and so on.
        let status = status_text(
            self.frames.shown.as_ref().map(|s| &s.update),
            self.document.doc.as_ref(),
            self.picking.pick.as_ref(),
            self.busy().as_deref(),
        );
        egui::Panel::bottom("status")
            .exact_size(24.0)
            .show(ui, |ui| ui.add(egui::Label::new(status).truncate()));
        egui::CentralPanel::default()
            .frame(egui::Frame::NONE)
            .show(ui, |ui| self.central(ui));
        help::show(&ctx, &mut self.help_open);
        self.handle_dialog(&ctx);

        self.submit_if_changed();
        // A button held down (a slider, the image) or the wheel turning: the change goes
        // on, and becomes one step when it ends.
        let changing =
            ctx.input(|i| i.pointer.any_down() || i.smooth_scroll_delta != egui::Vec2::ZERO);
        self.history.observe(&self.snapshot(), changing);
        if self.sequence.is_some()
            && self.frame_job.is_none()
            && self.opening.is_none()
            && self.frames.has_job()
        {
            self.frame_job = Some(self.generation);
        }
        let received = self.frames.receive(&ctx);
        if self.take_file_error(&ctx) {
            return;
        }
        self.after_frame(&ctx, received);
    }

    /// The file's checksum failed (verified beside the first frames) or a part of it
    /// failed its check when a frame read it (files are opened to be checked where they
    /// are read, see `dataset::render_options`): shown as an open's error would be, nothing
    /// more is rendered or saved of it, and a scripted run fails with it and writes
    /// nothing, as `render` does. `true` when the window is closing for it.
    pub(super) fn take_file_error(&mut self, ctx: &egui::Context) -> bool {
        let Some(message) = self.document.doc.as_ref().and_then(Doc::failure) else {
            return false;
        };
        if self.error.as_deref() != Some(message.as_str()) {
            self.error = Some(message.clone());
        }
        if self.script.is_none() {
            return false;
        }
        if let Ok(mut g) = self.outcome.lock() {
            *g = Some(Err(anyhow::anyhow!("{message}")));
        }
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        true
    }

    /// Playback and the script, once the frame's image is taken.
    fn after_frame(&mut self, ctx: &egui::Context, received: bool) {
        let on_screen = self.frame_on_screen();
        let (stepped, playing) = match &mut self.sequence {
            Some(p) => (p.tick(Instant::now(), on_screen), p.playing),
            None => (false, false),
        };
        if stepped {
            self.show_frame();
        }
        if playing {
            ctx.request_repaint();
        }
        let pending = self.background_pending();
        let Some(script) = &mut self.script else {
            return;
        };
        if pending {
            // `poll_background` asks for the frame that looks again.
            return;
        }
        let shown = self.frames.shown.as_ref().map(|s| &s.update);
        let no_image = self.document.doc.is_none() && self.sequence.is_none();
        let scale = self.frames.renderer().preview_scale();
        // Nothing is written before the file's checksum passed.
        let checked = !self
            .document
            .doc
            .as_ref()
            .is_some_and(Doc::checksum_pending);
        match script.after_frame(ctx, received, shown, scale, no_image, checked) {
            Ok(Some(report)) => {
                if let Ok(mut g) = self.outcome.lock() {
                    *g = Some(Ok(Some(report)));
                }
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            Ok(None) => ctx.request_repaint(),
            Err(e) => {
                if let Ok(mut g) = self.outcome.lock() {
                    *g = Some(Err(e));
                }
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
        if let Some(report) = script.report_mut() {
            report.threads = self.frames.renderer().threads();
            report.jobs = self.generation;
            report.window = [self.viewport_px[0], self.viewport_px[1]];
            report.first_ui_ms = self.first_ui_ms.unwrap_or(0.0);
            report.framed_ms = self.framed_ms.unwrap_or(0.0);
        }
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        ViewerApp::ui(self, ui);
    }
}
