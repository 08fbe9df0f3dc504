//! The images of the window: the progressive renderer, the view it works on, the image
//! on screen and the last finished one.

use std::sync::{Arc, OnceLock};

use eframe::egui::{self, ColorImage, TextureHandle, TextureOptions};

use crate::dataset::Dataset;
use crate::mesh::{MeshInstance, Meshes};
use crate::progressive::{Job, Level, Progressive, ProgressiveOptions, Update};
use crate::view_state::ViewState;

/// The image on screen and where it came from.
pub(crate) struct Shown {
    pub(crate) texture: TextureHandle,
    pub update: Update,
}

/// The link between the view and the renderer.
pub(crate) struct Frames {
    renderer: Progressive,
    /// Where the renderer's wake-ups go (the context, once a frame has shown it).
    pub(crate) repaint: Arc<OnceLock<egui::Context>>,
    /// The meshes of the view state, loaded when their list changes.
    pub(crate) meshes: Arc<Meshes>,
    meshes_for: Vec<MeshInstance>,
    pub(crate) shown: Option<Shown>,
    /// The newest finished full-resolution image (what "Save image" writes).
    pub(crate) finished: Option<Update>,
    /// The state the renderer is working on (`None`: render the next state whatever it is).
    submitted: Option<ViewState>,
}

impl Frames {
    /// Starts the renderer on `threads` (`None`: one per core), waking `ctx` when an image
    /// is ready.
    pub(crate) fn new(threads: Option<usize>, ctx: egui::Context) -> anyhow::Result<Frames> {
        let repaint: Arc<OnceLock<egui::Context>> = Arc::new(OnceLock::new());
        let _ = repaint.set(ctx);
        let r = Arc::clone(&repaint);
        let renderer = Progressive::new(
            ProgressiveOptions {
                threads,
                ..ProgressiveOptions::default()
            },
            Box::new(move || {
                if let Some(c) = r.get() {
                    c.request_repaint();
                }
            }),
        )?;
        Ok(Frames {
            renderer,
            repaint,
            meshes: Arc::new(Meshes::empty()),
            meshes_for: Vec::new(),
            shown: None,
            finished: None,
            submitted: None,
        })
    }

    pub(crate) fn renderer(&self) -> &Progressive {
        &self.renderer
    }

    /// Whether a view was handed to the renderer since the data last changed.
    pub(crate) fn has_job(&self) -> bool {
        self.submitted.is_some()
    }

    /// The data changed under the same view (another frame of a sequence): render again,
    /// and forget the finished image of the old data.
    pub(crate) fn data_changed(&mut self) {
        self.submitted = None;
        self.finished = None;
    }

    /// Hands `state` of `dataset` to the renderer if it changed since the last job;
    /// returns the new job's generation. Meshes are loaded here, on the UI thread, when
    /// their list changes (small files); a list that fails to load is put back and the
    /// error shown. A state that does not validate is shown as an error, not rendered.
    pub(crate) fn submit_if_changed(
        &mut self,
        dataset: &Arc<Dataset>,
        state: &mut ViewState,
        error: &mut Option<String>,
    ) -> Option<u64> {
        if self.submitted.as_ref() == Some(&*state) {
            return None;
        }
        if self.meshes_for != state.meshes {
            match Meshes::load(&state.meshes) {
                Ok(m) => {
                    self.meshes = Arc::new(m);
                    self.meshes_for = state.meshes.clone();
                }
                Err(e) => {
                    *error = Some(e.to_string());
                    state.meshes = self.meshes_for.clone();
                }
            }
        }
        if let Err(m) = state.validate() {
            *error = Some(format!("view state: {m}"));
            return None;
        }
        let generation = self.renderer.submit(Job {
            dataset: Arc::clone(dataset),
            meshes: Arc::clone(&self.meshes),
            state: state.clone(),
            preview: true,
        });
        self.submitted = Some(state.clone());
        Some(generation)
    }

    /// Takes the renderer's newest image into the texture; whether there was one.
    pub(crate) fn receive(&mut self, ctx: &egui::Context) -> bool {
        let Some(u) = self.renderer.latest() else {
            return false;
        };
        // The picture with its overlays, at the view's size (a preview scaled up, so the
        // overlays stay sharp while the view moves).
        let (w, h, rgb8) = u.picture();
        let image = ColorImage::from_rgb([w as usize, h as usize], &rgb8);
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
}
