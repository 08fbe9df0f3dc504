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
use crate::planes::HalfSpace;
use crate::sampling::{Params, Strategy};
use crate::shading::Shading;
use crate::transfer::{Mode, PreIntegrated, Transfer};
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
    /// The iso-surfaces beyond the first (iso mode), each with the acceleration of its
    /// value; empty in dvr mode, which draws the band around the first.
    pub more_surfaces: Vec<SurfaceTrace>,
    /// Style of the first iso-surface (its value and acceleration are `params` and
    /// `accel`).
    pub first_style: SurfaceStyle,
    /// Clip and slice planes in the volume's local frame.
    pub cuts: Cuts,
}

/// How an iso-surface is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceStyle {
    pub opacity: f64,
    /// A fixed colour instead of the colour map's.
    pub colour: Option<[f32; 3]>,
}

/// An iso-surface beyond the view's first: its ray parameters (the view's, at its
/// value) and the acceleration of that value.
pub struct SurfaceTrace {
    pub params: Params,
    pub accel: Arc<Accel>,
    pub style: SurfaceStyle,
}

/// A slice plane resolved for rays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliceTrace {
    pub plane: HalfSpace,
    pub opacity: f64,
    pub contours: bool,
}

/// The view's planes, resolved once per frame in the volume's local frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cuts {
    /// Every half-space a ray is cut to: the clip planes, and the slices that clip what
    /// lies in front of them (oriented away from the camera).
    pub clips: Vec<HalfSpace>,
    pub slices: Vec<SliceTrace>,
}

impl Cuts {
    /// The planes of `state` in `vol`'s local frame.
    pub fn new(vol: &Volume, state: &ViewState) -> Cuts {
        let frame = vol.frame;
        let mut clips: Vec<HalfSpace> = state
            .clip
            .iter()
            .map(|p| HalfSpace::new(p, frame))
            .collect();
        let eye = state.camera.eye;
        let forward: [f64; 3] = std::array::from_fn(|a| state.camera.look_at[a] - eye[a]);
        let local_eye: [f64; 3] = std::array::from_fn(|a| eye[a] - frame[a]);
        let slices = state
            .slices
            .iter()
            .map(|s| {
                let plane = HalfSpace::new(&s.plane, frame);
                if s.clip {
                    // Keep the side away from the camera; a camera on the plane keeps
                    // the side it looks into.
                    let side = plane.distance(&local_eye);
                    let away = if side != 0.0 {
                        side < 0.0
                    } else {
                        plane.n.iter().zip(forward).map(|(n, f)| n * f).sum::<f64>() >= 0.0
                    };
                    clips.push(if away {
                        plane
                    } else {
                        HalfSpace {
                            n: plane.n.map(|x| -x),
                            c: -plane.c,
                        }
                    });
                }
                SliceTrace {
                    plane,
                    opacity: s.opacity,
                    contours: s.contours,
                }
            })
            .collect();
        Cuts { clips, slices }
    }

    /// `[t0, t1]` of the ray `o + t d` (local frame) cut by every clip; `None` when
    /// nothing of it is left.
    #[inline]
    pub fn interval(&self, o: &[f64; 3], d: &[f64; 3], t0: f64, t1: f64) -> Option<(f64, f64)> {
        crate::planes::clip_interval(&self.clips, o, d, t0, t1)
    }
}

impl<'a> Scene<'a> {
    /// Resolves `state` against `vol` (see [`resolve`]) with an acceleration of its own.
    pub fn new(
        vol: &'a Volume<'a>,
        state: &'a ViewState,
        meshes: &'a Meshes,
    ) -> Result<Self, UnknownField> {
        let params = resolve(vol, state)?;
        let accel = Arc::new(Accel::new(params.accel_key()));
        let more = more_surfaces(state, &params, |key| Arc::new(Accel::new(key)));
        Ok(Scene::with_accel(vol, state, meshes, params, accel, more))
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
        let accel = cache.get(params.accel_key());
        let more = more_surfaces(state, &params, |key| cache.get(key));
        Ok(Scene::with_accel(vol, state, meshes, params, accel, more))
    }

    fn with_accel(
        vol: &'a Volume<'a>,
        state: &'a ViewState,
        meshes: &'a Meshes,
        mut params: Params,
        accel: Arc<Accel>,
        mut more_surfaces: Vec<SurfaceTrace>,
    ) -> Self {
        // Nothing outside the regions that can contribute is walked; an empty box (none
        // can) is one no ray enters.
        params.clip = Some(accel.clip(vol));
        for s in &mut more_surfaces {
            s.params.clip = Some(s.accel.clip(vol));
        }
        Scene {
            vol,
            state,
            meshes,
            params,
            rays: state.camera.ray_generator(state.width, state.height),
            shading: Shading::default(),
            accel,
            more_surfaces,
            first_style: SurfaceStyle {
                opacity: state.iso_opacity,
                colour: state.iso_colour,
            },
            cuts: Cuts::new(vol, state),
        }
    }

    /// Whether a ray's searches take the jitter that offsets their first sample: dvr and
    /// the sampled iso strategies do; `exact` iso-surfaces take none, so their camera
    /// rays skip its hash.
    pub(crate) fn uses_jitter(&self) -> bool {
        self.params.tf.mode == Mode::Dvr
            || self.params.strategy != Strategy::Exact
            || self
                .more_surfaces
                .iter()
                .any(|s| s.params.strategy != Strategy::Exact)
    }

    /// Whether rays see one opaque iso-surface (or a dvr band) and no slice: the
    /// frame's rays then stop at their first hit.
    pub(crate) fn is_single_opaque(&self) -> bool {
        self.more_surfaces.is_empty()
            && self.first_style.opacity >= 1.0
            && self.cuts.slices.is_empty()
    }
}

/// The surfaces of `state` beyond the first (iso mode only), each with the acceleration
/// `accel` gives for its key.
fn more_surfaces(
    state: &ViewState,
    params: &Params,
    mut accel: impl FnMut(crate::accel::AccelKey) -> Arc<Accel>,
) -> Vec<SurfaceTrace> {
    if state.mode != crate::transfer::Mode::Iso {
        return Vec::new();
    }
    state
        .more_isos
        .iter()
        .map(|s| {
            let mut p = *params;
            p.tf.iso = s.value;
            SurfaceTrace {
                accel: accel(p.accel_key()),
                params: p,
                style: SurfaceStyle {
                    opacity: s.opacity,
                    colour: s.colour,
                },
            }
        })
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame finds every region it needs, with its box, by the walks and descents that
    /// reach it: no strategy, mode or shading builds the table of every region (56 bytes
    /// a region, 0.9 GB for a billion cells), and the pictures still show the surface.
    #[test]
    fn no_frame_builds_the_table_of_every_region() {
        let f = |p: [f64; 3]| {
            let c = [8.3, 7.9, 8.1];
            (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f64>().sqrt()
        };
        let file = crate::testvol::nested(16, [0.25, -0.5, 0.0], &[("d", &f)], 8);
        let view = crate::testvol::open(&file).expect("open");
        let vol = Volume::new(&view).expect("volume");
        let meshes = Meshes::empty();
        for (mode, strategy, more) in [
            (Mode::Iso, Strategy::Exact, false),
            (Mode::Iso, Strategy::Exact, true),
            (Mode::Iso, Strategy::Uniform, false),
            (Mode::Iso, Strategy::Paper, false),
            (Mode::Iso, Strategy::Bisect, false),
            (Mode::Dvr, Strategy::Uniform, false),
        ] {
            let mut state = ViewState::default_for_volume(&vol);
            (state.mode, state.strategy) = (mode, strategy);
            (state.width, state.height) = (40, 30);
            state.set_iso(4.0);
            if more {
                state.iso_opacity = 0.5;
                state.more_isos.push(crate::view_state::IsoSurface {
                    value: 2.5,
                    opacity: 1.0,
                    colour: None,
                });
            }
            let scene = Scene::new(&vol, &state, &meshes).expect("scene");
            let frame = crate::render::render(&scene);
            if mode == Mode::Iso {
                assert!(
                    frame.hits > 50,
                    "{mode:?} {strategy:?}: {} hits",
                    frame.hits
                );
            }
            assert!(
                !vol.region_table_built(),
                "{mode:?} {strategy:?}, more surfaces: {more}"
            );
        }
        // What asks for a region by index builds it.
        let _ = vol.region(0);
        assert!(vol.region_table_built());
    }

    /// A view of a field other than the first packs one tree, which point location then
    /// shares (it reads no ranges), and its pictures are those of a volume whose point
    /// location packed field 0 first: colours, depths and surface values, bit for bit.
    #[test]
    fn a_view_of_another_field_packs_one_tree() {
        let d = |p: [f64; 3]| (0..3).map(|a| (p[a] - 8.0).powi(2)).sum::<f64>().sqrt();
        let e = |p: [f64; 3]| 10.0 - (p[0] - 7.7).abs() - 0.5 * (p[1] - 8.2).abs() - p[2] * 0.1;
        let file = crate::testvol::nested(16, [0.0; 3], &[("d", &d), ("e", &e)], 8);
        let view = crate::testvol::open(&file).expect("open");
        let meshes = Meshes::empty();
        let frame_of = |vol: &Volume| {
            let mut state = ViewState::default_for_volume(vol);
            (state.width, state.height) = (40, 30);
            state.iso_field = "e".into();
            state.set_iso(7.0);
            let scene = Scene::new(vol, &state, &meshes).expect("scene");
            crate::render::render(&scene)
        };
        let vol = Volume::new(&view).expect("volume");
        let frame = frame_of(&vol);
        assert!(frame.hits > 50, "{} hits", frame.hits);
        assert_eq!(
            vol.locate_field(),
            Some(1),
            "the view's tree locates points"
        );
        let first = Volume::new(&view).expect("volume");
        assert!(first.locate_tree().is_some());
        assert_eq!(first.locate_field(), Some(0));
        let other = frame_of(&first);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(frame.rgb, other.rgb);
        assert_eq!(bits(&frame.depth), bits(&other.depth));
        assert_eq!(bits(&frame.surface_values), bits(&other.surface_values));
    }

    /// Camera rays skip the jitter's hash only where nothing reads it: `exact` iso-surfaces
    /// (one or several, with slices); every sampled strategy and dvr take it.
    #[test]
    fn only_exact_iso_surfaces_go_without_jitter() {
        let f = |p: [f64; 3]| p[0] - 8.0;
        let file = crate::testvol::nested(16, [0.0; 3], &[("q", &f)], 8);
        let view = crate::testvol::open(&file).expect("open");
        let vol = Volume::new(&view).expect("volume");
        let meshes = Meshes::empty();
        for (mode, strategy, more, jittered) in [
            (Mode::Iso, Strategy::Exact, false, false),
            (Mode::Iso, Strategy::Exact, true, false),
            (Mode::Iso, Strategy::Uniform, false, true),
            (Mode::Iso, Strategy::Paper, false, true),
            (Mode::Iso, Strategy::Bisect, true, true),
            (Mode::Dvr, Strategy::Exact, false, true),
            (Mode::Dvr, Strategy::Uniform, false, true),
        ] {
            let mut state = ViewState::default_for_volume(&vol);
            state.mode = mode;
            state.strategy = strategy;
            state.set_iso(0.5);
            if more {
                state.iso_opacity = 0.5;
                state.more_isos.push(crate::view_state::IsoSurface {
                    value: 2.0,
                    opacity: 1.0,
                    colour: None,
                });
            }
            let scene = Scene::new(&vol, &state, &meshes).expect("scene");
            assert_eq!(
                scene.uses_jitter(),
                jittered,
                "{mode:?} {strategy:?}, more surfaces: {more}"
            );
        }
    }
}
