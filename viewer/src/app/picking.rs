//! Picking: the surface point and the field values under the cursor.

use std::sync::Arc;

use crate::dataset::{Dataset, DatasetAccels};
use crate::mesh::Meshes;
use crate::ray::RayCaster;
use crate::scene::Scene;
use crate::view_state::ViewState;

/// Field values at the point under the cursor.
#[derive(Debug, Clone)]
pub(crate) struct PickInfo {
    pub world: [f64; 3],
    pub values: Vec<(String, f32)>,
}

/// Whether the values under the cursor are shown, the last point picked, and the
/// accelerations picks walk (kept, so that picking under a moving cursor builds the
/// iso-surface's tree once, not at every move).
#[derive(Default)]
pub(crate) struct Picking {
    /// Pick continuously under the moving cursor ("pick values under the cursor").
    pub on: bool,
    pub pick: Option<PickInfo>,
    accels: DatasetAccels,
}

impl Picking {
    /// Forgets the point picked and the accelerations of the data shown so far (another
    /// file or frame is opened: its trees would only keep the old file mapped).
    pub(crate) fn forget(&mut self) {
        self.pick = None;
        self.accels = DatasetAccels::default();
    }

    /// The first surface (the iso-surface found with `exact`, or a mesh) under image
    /// position (`x`, `y`) in render pixels of the view `state` of `dataset`, and the
    /// field values there.
    pub(crate) fn pick_at(
        &mut self,
        dataset: &Arc<Dataset>,
        state: &ViewState,
        meshes: &Meshes,
        x: f64,
        y: f64,
    ) -> Option<PickInfo> {
        pick_at(dataset, state, meshes, &mut self.accels, x, y)
    }
}

fn pick_at(
    dataset: &Arc<Dataset>,
    state: &ViewState,
    meshes: &Meshes,
    accels: &mut DatasetAccels,
    x: f64,
    y: f64,
) -> Option<PickInfo> {
    let vol = dataset.volume();
    let scene = Scene::cached(vol, state, meshes, accels.of(dataset)).ok()?;
    let ray = scene.rays.ray(x, y);
    let mut caster = RayCaster::new(&scene);
    let t = caster.first_surface(&ray)?;
    let world = ray.at(t).to_array();
    let sample = vol.sample(world, scene.params.field);
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
