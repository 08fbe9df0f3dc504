//! A view resolved against a volume, once per frame: everything a ray needs.
//!
//! A [`ViewState`] names things (fields by name, a strategy that depends on the mode, a
//! band around the iso value); the rays need indices, the strategy actually used, the
//! band as numbers, and the trees of the view's acceleration. [`Scene::new`] finds them
//! once, so the ray code never looks a name or a tree up, and a view state that names a
//! field the file lacks is refused here, with the same error as everywhere a field is
//! named ([`UnknownField`]).

use std::sync::Arc;

use crate::accel::{Accel, AccelCache};
use crate::camera::RayGen;
use crate::fields::UnknownField;
use crate::mesh::Meshes;
use crate::sampling::Params;
use crate::shading::Shading;
use crate::transfer::{PreIntegrated, Transfer};
use crate::view_state::ViewState;
use crate::volume::Volume;

/// Everything a ray needs, resolved once per frame.
pub struct Scene<'a> {
    pub vol: &'a Volume<'a>,
    pub state: &'a ViewState,
    pub meshes: &'a Meshes,
    pub params: Params,
    /// Camera rays with the camera basis computed once per frame.
    pub rays: RayGen,
    /// Where shading normals come from.
    pub shading: Shading,
    /// The view's acceleration: the trees its rays walk, for the field and iso value of
    /// `params` (see [`crate::accel`]).
    pub accel: Arc<Accel>,
}

impl<'a> Scene<'a> {
    /// Resolves `state` against `vol` (see [`resolve`]) with an acceleration of its own.
    pub fn new(
        vol: &'a Volume<'a>,
        state: &'a ViewState,
        meshes: &'a Meshes,
    ) -> Result<Self, UnknownField> {
        let params = resolve(vol, state)?;
        let accel = Arc::new(Accel::new(vol, params.accel_key()));
        Ok(Scene::with_accel(vol, state, meshes, params, accel))
    }

    /// [`Scene::new`] with the acceleration taken from `cache`, which must hold
    /// accelerations of `vol` only: a view that differs from a recent one by its camera,
    /// lights or colours builds nothing.
    pub fn cached(
        vol: &'a Volume<'a>,
        state: &'a ViewState,
        meshes: &'a Meshes,
        cache: &mut AccelCache,
    ) -> Result<Self, UnknownField> {
        let params = resolve(vol, state)?;
        let accel = cache.get(vol, params.accel_key());
        Ok(Scene::with_accel(vol, state, meshes, params, accel))
    }

    fn with_accel(
        vol: &'a Volume<'a>,
        state: &'a ViewState,
        meshes: &'a Meshes,
        mut params: Params,
        accel: Arc<Accel>,
    ) -> Self {
        // Nothing outside the regions that can contribute is walked; an empty box (none
        // can) is one no ray enters.
        params.clip = Some(accel.clip());
        Scene {
            vol,
            state,
            meshes,
            params,
            rays: state.camera.ray_generator(state.width, state.height),
            shading: Shading::default(),
            accel,
        }
    }
}

/// The ray parameters of `state` in `vol`: the iso and colour fields' indices (a name the
/// file lacks is an error naming the view-state key), the strategy the mode uses
/// (`ViewState::effective_strategy`: `exact` is an iso-surface strategy), the transfer
/// function and its pre-integration table, the opacity's reference length. No clip box:
/// that is the acceleration's.
pub fn resolve(vol: &Volume, state: &ViewState) -> Result<Params, UnknownField> {
    let field = vol
        .field_index(&state.iso_field)
        .map_err(|e| e.named_by("iso_field"))?;
    // A colour field the file does not have is an error like a missing iso field (it
    // used to fall back silently to a constant colour).
    let colour_field = vol
        .field_index(&state.colormap.field)
        .map_err(|e| e.named_by("colormap.field"))?;
    let mut params = Params {
        strategy: state.effective_strategy(),
        step: state.step,
        tf: Transfer {
            mode: state.mode,
            iso: state.iso,
            band: state.transfer,
        },
        field,
        colour_field: Some(colour_field),
        // The seed report's opacities are per sample at step 0.5·dx of the finest grid.
        delta0: 0.5 * vol.finest_w,
        clip: None,
        preintegrated: None,
    };
    if state.preintegrated {
        params.preintegrated = PreIntegrated::new(&params.tf, params.delta0);
    }
    Ok(params)
}
