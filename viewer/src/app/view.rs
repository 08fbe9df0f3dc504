//! The window's view settings beside the view state: the light rig that follows the
//! camera, the meshes switched off and the mesh being typed; and the camera changes the
//! window makes on its own (put the lights back, frame the data).

use crate::mesh::MeshInstance;
use crate::palette::{Palette, PaletteSpec};
use crate::shading::{default_lights, Light};
use crate::view_state::ViewState;

use super::navigation;

/// Window-only settings of the view (not saved with the view state).
pub(crate) struct ViewControls {
    /// The default lights follow the camera (key light at `light_dir` in the camera frame).
    pub lights_follow: bool,
    /// Key light azimuth and elevation in degrees, relative to the camera.
    pub light_dir: [f32; 2],
    /// Meshes switched off in the panel (kept so they can be switched on again).
    pub hidden_meshes: Vec<MeshInstance>,
    /// The `--mesh`-style spec typed into the panel.
    pub mesh_spec: String,
    /// The colour-map preset the panel builds maps from (`--colormap`), and whether it
    /// spaces them in log10 (`--log`).
    pub palette: PaletteSpec,
    pub log: bool,
    /// The iso slider is symmetric-log (decades on both sides of zero).
    pub iso_log: bool,
}

impl Default for ViewControls {
    fn default() -> Self {
        ViewControls {
            lights_follow: true,
            light_dir: [-31.0, 34.4],
            hidden_meshes: Vec::new(),
            mesh_spec: String::new(),
            palette: PaletteSpec {
                palette: Palette::Speed,
                reversed: false,
            },
            log: false,
            iso_log: true,
        }
    }
}

impl ViewControls {
    /// Sets the key light from `light_dir` relative to the camera (and the fill light
    /// from the default rig), when the lights follow the camera.
    pub(crate) fn relight(&self, state: &mut ViewState) {
        if !self.lights_follow {
            return;
        }
        let cam = &state.camera;
        let mut lights = default_lights(cam);
        let b = cam.basis();
        let [az, el] = self.light_dir.map(|d| f64::from(d).to_radians());
        // Direction towards the light: azimuth from "behind the viewer" towards the
        // right, elevation up.
        let towards = el.cos() * (az.cos() * -b.forward + az.sin() * b.right) + el.sin() * b.up;
        if let Some(Light::Directional { direction, .. }) = lights.first_mut() {
            *direction = (-towards).to_array();
        }
        state.lights = lights;
    }
}

/// Points the camera of `state` at the box `min..max` (world), keeping its direction;
/// returns the new pivot.
pub(crate) fn frame_box(state: &mut ViewState, min: [f64; 3], max: [f64; 3]) -> [f64; 3] {
    let cam = navigation::frame_box(&state.camera, min, max);
    state.camera = cam;
    cam.look_at
}
