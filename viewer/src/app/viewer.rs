//! The window's state and its frame: the open file, the view state, the image shown,
//! mouse navigation, files in and out, the status line.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use eframe::egui::{self, Color32, ColorImage, Key, Sense, TextureHandle, TextureOptions};
use egui_file_dialog::FileDialog;
use glam::DVec3;

use super::navigation;
use super::player::Player;
use super::script::{ScriptRunner, ScriptStep};
use super::{OrbitReport, WindowOptions};
use crate::dataset::Dataset;
use crate::film;
use crate::mesh::{MeshInstance, Meshes};
use crate::progressive::{Job, Level, Progressive, ProgressiveOptions, Update};
use crate::ray::RayCaster;
use crate::render::Scene;
use crate::shading::{default_lights, Light};
use crate::view_state::{ViewState, MAX_IMAGE_SIDE};
use format::sequence::FramePattern;

/// The bundled sample, opened when no file is given.
pub(crate) const DEFAULT_FILE: &str = "data/wake_small.qbk";

/// Samples per pixel the window refines to when the view state does not say.
const WINDOW_SPP: u32 = 4;

/// An open file and what the panel shows about it.
pub(crate) struct Doc {
    pub dataset: Arc<Dataset>,
    pub path: PathBuf,
    pub cells: u64,
    pub bricks: usize,
    pub regions: usize,
    /// Per field: name, range and histogram (bins over `min..=max`).
    pub fields: Vec<FieldSummary>,
}

pub struct FieldSummary {
    pub name: String,
    pub min: f32,
    pub max: f32,
    pub histogram: Vec<u64>,
}

impl Doc {
    fn new(dataset: Dataset, path: &Path) -> Doc {
        let file = dataset.view().file();
        let cells = file.levels.iter().map(|l| l.cells.to_native()).sum();
        let fields = file
            .fields
            .iter()
            .map(|f| FieldSummary {
                name: f.name.to_string(),
                min: f.min.to_native(),
                max: f.max.to_native(),
                histogram: f.histogram.iter().map(|c| c.to_native()).collect(),
            })
            .collect();
        Doc {
            bricks: file.bricks.len(),
            regions: file.regions.len(),
            cells,
            fields,
            path: path.to_path_buf(),
            dataset: Arc::new(dataset),
        }
    }

    pub(crate) fn field(&self, name: &str) -> Option<&FieldSummary> {
        self.fields.iter().find(|f| f.name == name)
    }
}

/// Field values at the point under the cursor.
#[derive(Debug, Clone)]
pub(crate) struct PickInfo {
    pub world: [f64; 3],
    pub values: Vec<(String, f32)>,
}

/// What a file dialog was opened for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DialogPurpose {
    OpenFile,
    SavePng,
    SaveState,
    LoadState,
    AddMesh,
}

/// The image on screen and where it came from.
pub(crate) struct Shown {
    pub(crate) texture: TextureHandle,
    pub update: Update,
}

/// The window.
pub struct ViewerApp {
    pub(crate) doc: Option<Doc>,
    /// The view being shown; every panel control edits a field of it.
    pub state: ViewState,
    pub(crate) meshes: Arc<Meshes>,
    meshes_for: Vec<MeshInstance>,
    renderer: Progressive,
    repaint: Arc<OnceLock<egui::Context>>,
    pub(crate) shown: Option<Shown>,
    /// The newest finished full-resolution image (what "Save image" writes).
    pub(crate) finished: Option<Update>,
    /// The state the renderer is working on.
    submitted: Option<ViewState>,
    /// Generation of the job the renderer is working on.
    pub generation: u64,
    /// One-line message shown at the top of the panel (bad file, failed save, …).
    pub error: Option<String>,
    /// Point the camera orbits around.
    pub pivot: [f64; 3],
    /// Render resolution relative to the window's pixels.
    pub resolution_scale: f32,
    /// The default lights follow the camera (key light at `light_dir` in the camera frame).
    pub(crate) lights_follow: bool,
    /// Key light azimuth and elevation in degrees, relative to the camera.
    pub(crate) light_dir: [f32; 2],
    pub(crate) pick_mode: bool,
    pub(crate) pick: Option<PickInfo>,
    pub(crate) dialog: FileDialog,
    pub(crate) dialog_purpose: Option<DialogPurpose>,
    /// The `--mesh`-style spec typed into the panel.
    pub(crate) mesh_spec: String,
    /// Meshes switched off in the panel (kept so they can be switched on again).
    pub(crate) hidden_meshes: Vec<MeshInstance>,
    /// Image size in pixels the central area asks for.
    viewport_px: [u32; 2],
    script: Option<ScriptRunner>,
    /// The frames when the window was opened on a sequence pattern (`frame_####.qbk`).
    pub sequence: Option<Player>,
    /// Generation of the first job of the frame shown, so playback knows when that frame
    /// is on screen (`None`: not submitted yet).
    frame_job: Option<u64>,
    outcome: Arc<Mutex<Option<anyhow::Result<Option<OrbitReport>>>>>,
    /// The view state file loaded last (an input: saves must not overwrite it).
    state_file: Option<PathBuf>,
    /// The error of opening the file or the state the window was started with.
    startup_error: Option<String>,
    last_ui: Option<Instant>,
}

impl ViewerApp {
    /// A window on `options.file` (or the bundled sample). A file that fails to open is
    /// reported in the window, not as an error: the window still opens.
    pub(crate) fn new(
        ctx: egui::Context,
        options: WindowOptions,
        outcome: Arc<Mutex<Option<anyhow::Result<Option<OrbitReport>>>>>,
    ) -> anyhow::Result<ViewerApp> {
        let repaint: Arc<OnceLock<egui::Context>> = Arc::new(OnceLock::new());
        let _ = repaint.set(ctx);
        let r = Arc::clone(&repaint);
        let renderer = Progressive::new(
            ProgressiveOptions {
                threads: options.threads,
                ..ProgressiveOptions::default()
            },
            Box::new(move || {
                if let Some(c) = r.get() {
                    c.request_repaint();
                }
            }),
        )?;
        let mut app = ViewerApp {
            doc: None,
            state: ViewState::default_for(
                [0.0; 3],
                [1.0; 3],
                &[crate::view_state::FieldRange {
                    name: "q".into(),
                    min: 0.0,
                    max: 1.0,
                }],
            ),
            meshes: Arc::new(Meshes::empty()),
            meshes_for: Vec::new(),
            renderer,
            repaint,
            shown: None,
            finished: None,
            submitted: None,
            generation: 0,
            error: None,
            pivot: [0.0; 3],
            resolution_scale: 1.0,
            lights_follow: true,
            light_dir: [-31.0, 34.4],
            pick_mode: false,
            pick: None,
            dialog: FileDialog::new(),
            dialog_purpose: None,
            mesh_spec: String::new(),
            hidden_meshes: Vec::new(),
            viewport_px: [0, 0],
            script: options.script.map(ScriptRunner::new),
            sequence: None,
            frame_job: None,
            outcome,
            state_file: None,
            startup_error: None,
            last_ui: None,
        };
        let file = options
            .file
            .clone()
            .unwrap_or_else(|| PathBuf::from(DEFAULT_FILE));
        app.open_file(&file);
        if let Some(s) = &options.state {
            app.load_state(s);
        }
        app.startup_error = app.error.clone();
        Ok(app)
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
        app.repaint = Arc::new(OnceLock::new());
        Ok(app)
    }

    pub fn renderer(&self) -> &Progressive {
        &self.renderer
    }

    /// Path of the open file.
    pub fn file(&self) -> Option<&Path> {
        self.doc.as_ref().map(|d| d.path.as_path())
    }

    /// Opens `path`, or the sequence when it is a frame pattern (`frame_####.qbk`) that is
    /// not itself a file; on failure the error is shown and the current file stays open.
    pub(crate) fn open_file(&mut self, path: &Path) {
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
        match Dataset::open(path) {
            Ok(ds) => {
                let doc = Doc::new(ds, path);
                let mut state = ViewState::default_for_volume(doc.dataset.volume());
                state.spp = WINDOW_SPP;
                state.width = self.state.width;
                state.height = self.state.height;
                self.pivot = state.camera.look_at;
                self.state = state;
                self.doc = Some(doc);
                self.error = None;
                self.finished = None;
                self.pick = None;
                self.sequence = None;
            }
            Err(e) => self.error = Some(e.to_string()),
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
        let mut state = info.default_state();
        state.spp = WINDOW_SPP;
        state.width = self.state.width;
        state.height = self.state.height;
        self.pivot = state.camera.look_at;
        self.state = state;
        self.lights_follow = true;
        self.sequence = Some(Player::new(shown, frames));
        self.doc = None;
        self.show_frame();
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
        self.pick = None;
        self.finished = None;
        match Dataset::open(&path) {
            Ok(ds) => {
                self.doc = Some(Doc::new(ds, &path));
                self.error = None;
                // The view did not change, the data did: render again.
                self.submitted = None;
                self.frame_job = None;
            }
            Err(e) => {
                self.error = Some(e.to_string());
                // Counts as shown, so playback does not stall on it.
                self.frame_job = Some(0);
            }
        }
    }

    /// Whether an image of the current frame is on screen (a preview counts).
    fn frame_on_screen(&self) -> bool {
        match (self.frame_job, &self.shown) {
            (Some(0), _) => true,
            (Some(g), Some(s)) => s.update.generation >= g,
            _ => false,
        }
    }

    /// Loads a view state file; it must name fields of the open file.
    pub fn load_state(&mut self, path: &Path) {
        let loaded = ViewState::load(path)
            .map_err(|e| e.to_string())
            .and_then(|s| {
                let doc = self.doc.as_ref().ok_or("no file is open")?;
                for name in [&s.iso_field, &s.colormap.field] {
                    if doc.field(name).is_none() {
                        return Err(format!(
                            "{}: field {name:?} is not in {}",
                            path.display(),
                            doc.path.display()
                        ));
                    }
                }
                Ok(s)
            });
        match loaded {
            Ok(s) => {
                self.pivot = s.camera.look_at;
                // The loaded lights are the user's: keep them where they are.
                self.lights_follow = false;
                self.state = s;
                self.state_file = Some(path.to_path_buf());
                self.error = None;
            }
            Err(m) => self.error = Some(m),
        }
    }

    /// Refuses to save over a file the window reads: the open file (every frame of an open
    /// sequence), the view state it loaded, the meshes (shown or hidden). The same guard
    /// every command's outputs go through.
    fn check_output(&self, role: &str, path: &Path) -> Result<(), String> {
        let mut guard = files::guard::Guard::new();
        if let Some(doc) = &self.doc {
            guard.input("open file", &doc.path);
        }
        if let Some(p) = &self.sequence {
            for (f, path) in &p.frames {
                guard.input(format!("frame {f}"), path);
            }
        }
        if let Some(s) = &self.state_file {
            guard.input("view state", s);
        }
        for m in self.state.meshes.iter().chain(&self.hidden_meshes) {
            guard.input("mesh", &m.path);
        }
        guard.output(role, path);
        guard.check().map_err(|e| e.to_string())
    }

    /// Writes the view state (the same JSON `render --state` reads).
    pub fn save_state(&mut self, path: &Path) {
        let result = self
            .check_output("Save view", path)
            .and_then(|()| self.state.save(path).map_err(|e| e.to_string()));
        if let Err(m) = result {
            self.error = Some(m);
        }
    }

    /// Writes the finished full-resolution image as a PNG.
    pub fn save_png(&mut self, path: &Path) {
        let result = match &self.finished {
            Some(u) => self.check_output("Save image", path).and_then(|()| {
                film::save_png(path, u.width, u.height, &u.rgb).map_err(|e| e.to_string())
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

    /// Frames the whole data set again.
    pub(crate) fn frame_data(&mut self) {
        if let Some(doc) = &self.doc {
            let vol = doc.dataset.volume();
            let cam = navigation::frame_box(
                &self.state.camera,
                vol.to_world(vol.bounds_min),
                vol.to_world(vol.bounds_max),
            );
            self.state.camera = cam;
            self.pivot = cam.look_at;
        }
    }

    /// Sets the key light from `light_dir` relative to the camera (and the fill light
    /// from the default rig), when the lights follow the camera.
    pub(crate) fn relight(&mut self) {
        if !self.lights_follow {
            return;
        }
        let cam = &self.state.camera;
        let mut lights = default_lights(cam);
        let b = cam.basis();
        let [az, el] = self.light_dir.map(|d| f64::from(d).to_radians());
        // Direction towards the light: azimuth from "behind the viewer" towards the
        // right, elevation up.
        let towards = el.cos() * (az.cos() * -b.forward + az.sin() * b.right) + el.sin() * b.up;
        if let Some(Light::Directional { direction, .. }) = lights.first_mut() {
            *direction = (-towards).to_array();
        }
        self.state.lights = lights;
    }

    /// Hands the view to the renderer if it changed since the last job.
    fn submit_if_changed(&mut self) {
        let Some(doc) = &self.doc else {
            return;
        };
        if self.submitted.as_ref() == Some(&self.state) {
            return;
        }
        // Meshes are loaded on the UI thread when their list changes (small files).
        if self.meshes_for != self.state.meshes {
            match Meshes::load(&self.state.meshes) {
                Ok(m) => {
                    self.meshes = Arc::new(m);
                    self.meshes_for = self.state.meshes.clone();
                }
                Err(e) => {
                    self.error = Some(e.to_string());
                    self.state.meshes = self.meshes_for.clone();
                }
            }
        }
        if let Err(m) = self.state.validate() {
            self.error = Some(format!("view state: {m}"));
            return;
        }
        self.generation = self.renderer.submit(Job {
            dataset: Arc::clone(&doc.dataset),
            meshes: Arc::clone(&self.meshes),
            state: self.state.clone(),
            preview: true,
        });
        self.submitted = Some(self.state.clone());
    }

    /// Takes the renderer's newest image into the texture.
    fn receive(&mut self, ctx: &egui::Context) -> bool {
        let Some(u) = self.renderer.latest() else {
            return false;
        };
        let rgb8 = film::to_rgb8(&u.rgb);
        let image = ColorImage::from_rgb([u.width as usize, u.height as usize], &rgb8);
        let options = match u.level {
            Level::Preview { .. } => TextureOptions::LINEAR,
            Level::Full => TextureOptions::NEAREST,
        };
        match &mut self.shown {
            Some(s) => {
                s.texture.set(image, options);
                s.update = u.clone();
            }
            None => {
                self.shown = Some(Shown {
                    texture: ctx.load_texture("frame", image, options),
                    update: u.clone(),
                })
            }
        }
        if u.complete {
            self.finished = Some(u);
        }
        true
    }

    /// Surface point and field values under image position (`x`, `y`) in render pixels.
    pub(crate) fn pick_at(&self, x: f64, y: f64) -> Option<PickInfo> {
        let doc = self.doc.as_ref()?;
        let vol = doc.dataset.volume();
        let scene = Scene::new(vol, &self.state, &self.meshes).ok()?;
        let ray = scene.rays.ray(x, y);
        let mut caster = RayCaster::new(&scene);
        let t = caster.first_surface(&ray)?;
        let world = ray.at(t).to_array();
        let field = vol.field_index(&self.state.iso_field).ok()?;
        let sample = vol.sample(world, field);
        let values = match sample {
            Some(s) => vol
                .fields
                .iter()
                .zip(s.values)
                .map(|(f, v)| (f.name.clone(), v))
                .collect(),
            None => Vec::new(), // a mesh outside the data
        };
        Some(PickInfo { world, values })
    }

    /// Handles dropped files: a `.json` is a view state, an `.obj` a mesh, anything else
    /// a brick file.
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

    /// Opens a file by its kind (extension).
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

    fn handle_dialog(&mut self, ctx: &egui::Context) {
        self.dialog.update(ctx);
        let Some(path) = self.dialog.take_picked() else {
            return;
        };
        match self.dialog_purpose.take() {
            Some(DialogPurpose::OpenFile) => self.open_file(&path),
            Some(DialogPurpose::SavePng) => self.save_png(&path),
            Some(DialogPurpose::SaveState) => self.save_state(&path),
            Some(DialogPurpose::LoadState) => self.load_state(&path),
            Some(DialogPurpose::AddMesh) => {
                self.mesh_spec = path.display().to_string();
                self.add_mesh_from_spec();
            }
            None => {}
        }
    }

    /// Adds the mesh typed as `PATH[@x,y,z,scale]`.
    pub(crate) fn add_mesh_from_spec(&mut self) {
        match MeshInstance::parse(self.mesh_spec.trim()) {
            Ok(m) => {
                self.state.meshes.push(m);
                self.mesh_spec.clear();
            }
            Err(e) => self.error = Some(format!("mesh: {e}")),
        }
    }

    pub(crate) fn open_dialog(&mut self, purpose: DialogPurpose) {
        self.dialog_purpose = Some(purpose);
        match purpose {
            DialogPurpose::SavePng | DialogPurpose::SaveState => self.dialog.save_file(),
            _ => self.dialog.pick_file(),
        }
    }

    /// The central image: navigation input and the picture.
    fn central(&mut self, ui: &mut egui::Ui) {
        let rect = ui.available_rect_before_wrap();
        let ppp = ui.ctx().pixels_per_point();
        let want = [rect.width(), rect.height()]
            .map(|s| ((s * ppp * self.resolution_scale).round() as u32).clamp(1, MAX_IMAGE_SIDE));
        if want != self.viewport_px || [self.state.width, self.state.height] != want {
            self.viewport_px = want;
            self.state.width = want[0];
            self.state.height = want[1];
        }
        let response = ui.allocate_rect(rect, Sense::click_and_drag());
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 0.0, Color32::from_rgb(20, 22, 26));
        if let Some(s) = &self.shown {
            painter.image(
                s.texture.id(),
                rect,
                egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                Color32::WHITE,
            );
        } else if self.doc.is_none() {
            painter.text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "Open a .qbk file (File > Open, or drop it here)",
                egui::FontId::proportional(18.0),
                Color32::LIGHT_GRAY,
            );
        }
        let to_px = |p: egui::Pos2| -> (f64, f64) {
            let u = (p - rect.min) / rect.size();
            (
                f64::from(u.x) * f64::from(self.state.width),
                f64::from(u.y) * f64::from(self.state.height),
            )
        };
        let (w, h) = (f64::from(self.state.width), f64::from(self.state.height));
        let px_per_point = w / f64::from(rect.width().max(1.0));
        let shift = ui.input(|i| i.modifiers.shift);
        let mut moved = false;
        if response.dragged_by(egui::PointerButton::Primary) && !shift {
            let d = response.drag_delta();
            navigation::orbit(
                &mut self.state.camera,
                self.pivot,
                -f64::from(d.x) * navigation::ORBIT_PER_PIXEL,
                f64::from(d.y) * navigation::ORBIT_PER_PIXEL,
            );
            moved = true;
        } else if response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
            || (response.dragged_by(egui::PointerButton::Primary) && shift)
        {
            let d = response.drag_delta();
            self.pivot = navigation::pan(
                &mut self.state.camera,
                self.pivot,
                f64::from(d.x) * px_per_point,
                f64::from(d.y) * px_per_point,
                w,
                h,
            );
            moved = true;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                let at = response
                    .hover_pos()
                    .map(to_px)
                    .unwrap_or((0.5 * w, 0.5 * h));
                navigation::zoom(
                    &mut self.state.camera,
                    self.pivot,
                    (-f64::from(scroll) * 0.002).exp(),
                    at.0,
                    at.1,
                    self.state.width,
                    self.state.height,
                );
                moved = true;
            }
        }
        if response.double_clicked() {
            if let Some(p) = response.interact_pointer_pos() {
                let (x, y) = to_px(p);
                if let Some(hit) = self.pick_at(x, y) {
                    self.pivot = hit.world;
                    self.pick = Some(hit);
                }
            }
        }
        if self.pick_mode {
            if let Some(p) = response.hover_pos() {
                if ui.input(|i| i.pointer.delta() != egui::Vec2::ZERO) || self.pick.is_none() {
                    let (x, y) = to_px(p);
                    self.pick = self.pick_at(x, y);
                }
            }
        }
        // Mark the pivot while navigating.
        if response.dragged() {
            let rays = self.state.camera.basis();
            let eye = DVec3::from_array(self.state.camera.eye);
            if (DVec3::from_array(self.pivot) - eye).dot(rays.forward) > 0.0 {
                painter.circle_stroke(rect.center(), 3.0, (1.0, Color32::from_white_alpha(120)));
            }
        }
        if moved {
            self.relight();
        }
    }

    fn status_line(&self, ui: &mut egui::Ui) {
        let text = self.status_text();
        ui.add(egui::Label::new(text).truncate());
    }

    /// The status line: the image shown, the file, the picked point.
    fn status_text(&self) -> String {
        let mut parts = Vec::new();
        match &self.shown {
            Some(s) => {
                let u = &s.update;
                let rays = u.counts.rays.max(1) as f64;
                let level = match u.level {
                    Level::Preview { scale } => format!("preview 1/{scale}"),
                    Level::Full if u.complete => format!("full, {} spp", u.samples),
                    Level::Full => format!("full, {}/{} spp", u.samples, u.spp),
                };
                parts.push(format!(
                    "{:.1} ms · {level} · {}×{} · {:.2} samples/ray · {:.2} Mrays/s",
                    u.ms,
                    u.width,
                    u.height,
                    u.counts.stats.samples as f64 / rays,
                    u.counts.rays as f64 / (u.ms.max(1e-3) * 1e3),
                ));
            }
            None => parts.push("no image yet".to_string()),
        }
        if let Some(doc) = &self.doc {
            parts.push(format!(
                "{} cells · {} bricks · {} regions",
                doc.cells, doc.bricks, doc.regions
            ));
        }
        if let Some(p) = &self.pick {
            let vals: Vec<String> = p
                .values
                .iter()
                .map(|(n, v)| format!("{n} {v:.4}"))
                .collect();
            parts.push(format!(
                "at ({:.3}, {:.3}, {:.3}): {}",
                p.world[0],
                p.world[1],
                p.world[2],
                if vals.is_empty() {
                    "outside the data".to_string()
                } else {
                    vals.join(", ")
                }
            ));
        }
        parts.join("  |  ")
    }

    /// One frame of the window (also what the UI tests drive).
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let ctx = ui.ctx().clone();
        let _ = self.repaint.set(ctx.clone());
        let now = Instant::now();
        let frame_interval = self.last_ui.map(|t| now.duration_since(t));
        self.last_ui = Some(now);

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
        if let Some(script) = &mut self.script {
            if let ScriptStep::Orbit(yaw) = script.before_frame(frame_interval) {
                navigation::orbit(&mut self.state.camera, self.pivot, yaw, 0.0);
                self.relight();
            }
        }
        self.take_dropped(&ctx);
        if ctx.input(|i| i.key_pressed(Key::F) || i.key_pressed(Key::Home))
            && !ctx.egui_wants_keyboard_input()
        {
            self.frame_data();
            self.relight();
        }

        egui::Panel::left("controls")
            .resizable(true)
            .default_size(300.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| super::panel::show(self, ui));
            });
        // One line of fixed height: a status text that wrapped to two lines would shrink
        // the image, which changes the render size, which starts a new frame, whose
        // status text is shorter again, and so on.
        egui::Panel::bottom("status")
            .exact_size(24.0)
            .show(ui, |ui| self.status_line(ui));
        egui::CentralPanel::default()
            .frame(egui::Frame::NONE)
            .show(ui, |ui| self.central(ui));
        self.handle_dialog(&ctx);

        self.submit_if_changed();
        if self.sequence.is_some() && self.frame_job.is_none() && self.submitted.is_some() {
            self.frame_job = Some(self.generation);
        }
        let received = self.receive(&ctx);
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
        if let Some(script) = &mut self.script {
            let shown = self.shown.as_ref().map(|s| &s.update);
            let no_image = self.doc.is_none() && self.sequence.is_none();
            let scale = self.renderer.preview_scale();
            match script.after_frame(&ctx, received, shown, scale, no_image) {
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
                report.threads = self.renderer.threads();
                report.jobs = self.generation;
                report.window = [self.viewport_px[0], self.viewport_px[1]];
            }
        }
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        ViewerApp::ui(self, ui);
    }
}
