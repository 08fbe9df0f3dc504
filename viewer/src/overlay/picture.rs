//! A view's picture: the rendered colours as 8-bit pixels with the view's overlays drawn
//! in. Every command that writes or shows a picture (`render`, its sequences, the
//! window's canvas, Save image… and `--screenshot`) makes it here, so they cannot differ.

use super::{draw, LegendInfo, OverlayInfo};
use crate::film::to_rgb8;
use crate::render::Frame;
use crate::view_state::ViewState;
use crate::volume::Volume;

/// The data's box in world coordinates (the union of the baked supports): the outline.
pub fn data_bounds(vol: &Volume) -> ([f64; 3], [f64; 3]) {
    (
        std::array::from_fn(|a| vol.bounds_min[a] + vol.frame[a]),
        std::array::from_fn(|a| vol.bounds_max[a] + vol.frame[a]),
    )
}

/// Draws `state`'s overlays into `rgb8` (`width`×`height` 8-bit RGB, row-major) of a view
/// of data with box `bounds`. `depth` (per pixel, the distance to the first surface, see
/// [`Frame::depth`]) hides the outline behind surfaces; without it the outline is drawn
/// on top. `title` is the title line's text (shown when the title overlay is on).
pub fn annotate(
    rgb8: &mut [u8],
    width: u32,
    height: u32,
    state: &ViewState,
    bounds: Option<([f64; 3], [f64; 3])>,
    depth: Option<&[f32]>,
    title: Option<&str>,
) {
    if !state.overlays.any() {
        return;
    }
    let depth = depth.filter(|d| d.len() == width as usize * height as usize);
    // Dvr draws the band around the first value only.
    let isos: Vec<f64> = match state.mode {
        crate::transfer::Mode::Iso => state.surfaces().iter().map(|s| s.value).collect(),
        crate::transfer::Mode::Dvr => vec![state.iso],
    };
    let info = OverlayInfo {
        rays: state.camera.ray_generator(width, height),
        pivot: state.camera.look_at,
        bounds,
        clip: &state.clip,
        slices: &state.slices,
        depth,
        legend: Some(LegendInfo {
            colormap: &state.colormap,
            iso_field: &state.iso_field,
            isos: &isos,
        }),
        title,
        background: state.background,
    };
    draw(rgb8, width, height, &state.overlays, &info);
}

/// The picture of `frame`, rendered from `state` over data with box `bounds`: its 8-bit
/// pixels with the overlays drawn in, the outline hidden behind the frame's surfaces.
pub fn picture(
    frame: &Frame,
    state: &ViewState,
    bounds: Option<([f64; 3], [f64; 3])>,
    title: Option<&str>,
) -> Vec<u8> {
    let mut rgb8 = to_rgb8(&frame.rgb);
    annotate(
        &mut rgb8,
        frame.width,
        frame.height,
        state,
        bounds,
        Some(&frame.depth),
        title,
    );
    rgb8
}

/// The 8-bit picture a render of `vol` writes: [`picture`] with the data's box, or, for
/// an `aov` debug buffer, its pixels alone (a buffer is for reading values, not a figure).
pub fn figure(frame: &Frame, state: &ViewState, vol: &Volume, aov: bool, title: &str) -> Vec<u8> {
    if aov {
        return to_rgb8(&frame.rgb);
    }
    picture(frame, state, Some(data_bounds(vol)), Some(title))
}

/// The default title of a file's picture: its name.
pub fn file_title(path: &std::path::Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}
