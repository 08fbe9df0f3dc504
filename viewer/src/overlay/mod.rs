//! Overlays: what makes a picture explain itself — the colour legend, an axis triad, the
//! data's outline box, a scale bar and a title line.
//!
//! They are drawn into the finished 8-bit image, after the samples are resolved, so they
//! stay crisp at any samples per pixel and cost a few milliseconds at any size; every
//! command that writes a picture (`render`, its sequences, the window's Save image and
//! `--screenshot`) draws them the same way from the same [`OverlayInfo`]. Sizes follow the
//! image (a unit of `min(width, height) / 480` pixels), so the legend reads the same at
//! 640×480 and at 4K. Each overlay keeps to its own part of the picture: the legend on
//! the right, the triad bottom left, the scale bar bottom right, the title top left; the
//! box is drawn where the data is, hidden behind surfaces in front of it, with the
//! outlines of the view's clip planes and slices where they cross it.

mod axes;
pub mod canvas;
mod legend;
mod outline;
mod picture;
mod scale;
pub mod ticks;

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::camera::RayGen;
use crate::colormap::ColorMap;
use crate::planes::{Plane, Slice};
use canvas::Canvas;
pub use picture::{annotate, data_bounds, figure, file_title, picture};

/// Which overlays a picture carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Overlays {
    pub legend: bool,
    pub axes: bool,
    /// The data's outline box (and where the clip planes and slices cross it).
    pub outline: bool,
    pub scale: bool,
    pub title: bool,
}

/// The names of the overlays, as the command line and the view state write them.
pub const NAMES: [&str; 5] = ["legend", "axes", "box", "scale", "title"];

impl Overlays {
    /// No overlay: the bare picture.
    pub const NONE: Overlays = Overlays {
        legend: false,
        axes: false,
        outline: false,
        scale: false,
        title: false,
    };

    fn flag(&mut self, name: &str) -> Option<&mut bool> {
        match name {
            "legend" => Some(&mut self.legend),
            "axes" => Some(&mut self.axes),
            "box" => Some(&mut self.outline),
            "scale" => Some(&mut self.scale),
            "title" => Some(&mut self.title),
            _ => None,
        }
    }

    fn names(&self) -> Vec<&'static str> {
        let on = [self.legend, self.axes, self.outline, self.scale, self.title];
        NAMES
            .iter()
            .zip(on)
            .filter_map(|(n, on)| on.then_some(*n))
            .collect()
    }

    /// Whether any overlay is on.
    pub fn any(&self) -> bool {
        *self != Overlays::NONE
    }
}

/// Every overlay but the title: a picture that says what its colours mean, where its axes
/// point and how large it is.
impl Default for Overlays {
    fn default() -> Self {
        Overlays {
            legend: true,
            axes: true,
            outline: true,
            scale: true,
            title: false,
        }
    }
}

/// Why an overlay list does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("expected `none` or a comma-separated list of {}, found `{text}`", NAMES.join(", "))]
pub struct OverlaysError {
    pub text: String,
}

impl FromStr for Overlays {
    type Err = OverlaysError;
    fn from_str(s: &str) -> Result<Self, OverlaysError> {
        let bad = || OverlaysError {
            text: s.to_string(),
        };
        let s = s.trim();
        if s == "none" {
            return Ok(Overlays::NONE);
        }
        let mut o = Overlays::NONE;
        for name in s.split(',').map(str::trim) {
            *o.flag(name).ok_or_else(bad)? = true;
        }
        Ok(o)
    }
}

impl fmt::Display for Overlays {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names = self.names();
        if names.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&names.join(","))
        }
    }
}

/// In a view state: the list of names that are on (`[]` for none).
impl Serialize for Overlays {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.names().serialize(s)
    }
}

impl<'de> Deserialize<'de> for Overlays {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let names: Vec<String> = Vec::deserialize(d)?;
        let mut o = Overlays::NONE;
        for n in &names {
            let flag = o
                .flag(n)
                .ok_or_else(|| serde::de::Error::unknown_variant(n, &NAMES))?;
            *flag = true;
        }
        Ok(o)
    }
}

/// What the legend shows.
#[derive(Debug, Clone, Copy)]
pub struct LegendInfo<'a> {
    /// The map whose colours the picture shows; its field names the legend.
    pub colormap: &'a ColorMap,
    /// The field of the iso values, and the values: marked on the bar when they are of
    /// the colour field, written under it otherwise.
    pub iso_field: &'a str,
    pub isos: &'a [f64],
}

/// What the overlays are drawn from.
#[derive(Debug, Clone, Copy)]
pub struct OverlayInfo<'a> {
    /// The camera rays of the picture (its size and projection).
    pub rays: RayGen,
    /// The point the camera orbits around: where a perspective scale bar is true.
    pub pivot: [f64; 3],
    /// The data's box (world), for the outline.
    pub bounds: Option<([f64; 3], [f64; 3])>,
    /// The view's clip planes and slices, outlined where they cross the box (with the
    /// box overlay).
    pub clip: &'a [Plane],
    pub slices: &'a [Slice],
    /// Per pixel (row-major), the ray parameter of the first surface, infinite where
    /// there is none: the outline is hidden behind surfaces. `None`: drawn on top.
    pub depth: Option<&'a [f32]>,
    pub legend: Option<LegendInfo<'a>>,
    pub title: Option<&'a str>,
    /// The picture's background colour: text and panels take the contrasting shade.
    pub background: [f32; 3],
}

/// Sizes and colours of one picture's overlays.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Style {
    /// Layout unit, pixels: `min(width, height) / 480`.
    pub u: f64,
    /// Text size, pixels.
    pub font: f64,
    /// Distance of every overlay from the picture's edges.
    pub margin: f64,
    pub ink: [f32; 3],
    /// The shade under text and behind panels.
    pub paper: [f32; 3],
}

impl Style {
    fn for_image(width: u32, height: u32, background: [f32; 3]) -> Style {
        let u = (f64::from(width.min(height)) / 480.0).max(0.5);
        let luma = 0.2126 * background[0] + 0.7152 * background[1] + 0.0722 * background[2];
        let (ink, paper) = if luma > 0.5 {
            ([0.05, 0.05, 0.06], [1.0, 1.0, 1.0])
        } else {
            ([1.0, 1.0, 1.0], [0.05, 0.05, 0.06])
        };
        Style {
            u,
            font: (15.0 * u).max(11.0),
            margin: 12.0 * u,
            ink,
            paper,
        }
    }
}

/// Draws the overlays `which` into the 8-bit RGB image `rgb8` (`width`×`height`, row-major,
/// as [`crate::film::to_rgb8`] makes it). An image of another size is left alone.
pub fn draw(rgb8: &mut [u8], width: u32, height: u32, which: &Overlays, info: &OverlayInfo) {
    let Some(mut canvas) = Canvas::new(rgb8, width, height) else {
        return;
    };
    let style = Style::for_image(width, height, info.background);
    if which.outline {
        if let Some((lo, hi)) = info.bounds {
            outline::draw(&mut canvas, &style, &info.rays, lo, hi, info.depth);
            outline::planes(
                &mut canvas,
                &style,
                &info.rays,
                lo,
                hi,
                info.clip,
                info.slices,
                info.depth,
            );
        }
    }
    if which.axes {
        axes::draw(&mut canvas, &style, &info.rays);
    }
    if which.scale {
        scale::draw(&mut canvas, &style, &info.rays, info.pivot);
    }
    if which.legend {
        if let Some(l) = &info.legend {
            legend::draw(&mut canvas, &style, l);
        }
    }
    if which.title {
        if let Some(t) = info.title {
            let y = style.margin + canvas::cap_height(style.font * 1.15);
            canvas.text_with_halo(
                style.margin,
                y,
                style.font * 1.15,
                t,
                style.ink,
                style.paper,
                style.u.max(1.0),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Camera, Projection};
    use crate::colormap::ColorMap;

    /// A mid-grey picture with every input an overlay needs.
    fn picture(
        which: Overlays,
        w: u32,
        h: u32,
        depth: Option<&[f32]>,
        projection: Projection,
    ) -> Vec<u8> {
        with_planes(which, w, h, depth, projection, &[], &[])
    }

    fn camera(projection: Projection) -> Camera {
        Camera {
            eye: [3.0, -4.0, 2.5],
            look_at: [0.0, 0.0, 0.0],
            up: [0.0, 0.0, 1.0],
            projection,
        }
    }

    /// [`picture`] of a view with clip planes and slices.
    fn with_planes(
        which: Overlays,
        w: u32,
        h: u32,
        depth: Option<&[f32]>,
        projection: Projection,
        clip: &[Plane],
        slices: &[Slice],
    ) -> Vec<u8> {
        let cam = camera(projection);
        let map = ColorMap::default_for_range("speed", 0.0, 0.09);
        let mut px = vec![60u8; 3 * (w * h) as usize];
        let info = OverlayInfo {
            rays: cam.ray_generator(w, h),
            pivot: cam.look_at,
            bounds: Some(([-1.0, -0.5, -0.5], [1.0, 0.5, 0.5])),
            clip,
            slices,
            depth,
            legend: Some(LegendInfo {
                colormap: &map,
                iso_field: "speed",
                isos: &[0.05],
            }),
            title: Some("wake_small.qbk, frame 3"),
            background: [0.08, 0.09, 0.11],
        };
        draw(&mut px, w, h, &which, &info);
        px
    }

    fn changed(a: &[u8], b: &[u8]) -> Vec<usize> {
        (0..a.len() / 3)
            .filter(|&i| a[3 * i..3 * i + 3] != b[3 * i..3 * i + 3])
            .collect()
    }

    /// No overlay leaves the picture as it was; each overlay changes pixels, its own part
    /// of the picture only (the legend on the right, the triad bottom left, the scale bar
    /// bottom right, the title top left), and all of them change exactly the union.
    #[test]
    fn each_overlay_changes_only_its_own_pixels() {
        let (w, h) = (640u32, 480u32);
        let persp = Projection::Perspective { fov_deg: 35.0 };
        let bare = picture(Overlays::NONE, w, h, None, persp);
        assert!(bare.iter().all(|&b| b == 60));
        let single = |name: &str| {
            let o: Overlays = name.parse().expect("name");
            changed(&bare, &picture(o, w, h, None, persp))
        };
        let region = |i: usize| {
            (
                (i as u32 % w) as f64 / f64::from(w),
                (i as u32 / w) as f64 / f64::from(h),
            )
        };
        let legend = single("legend");
        assert!(
            legend.iter().all(|&i| region(i).0 > 0.7),
            "legend outside the right"
        );
        let axes = single("axes");
        assert!(axes.iter().all(|&i| region(i).0 < 0.3 && region(i).1 > 0.6));
        let scale = single("scale");
        assert!(scale
            .iter()
            .all(|&i| region(i).0 > 0.5 && region(i).1 > 0.85));
        let title = single("title");
        assert!(title
            .iter()
            .all(|&i| region(i).0 < 0.6 && region(i).1 < 0.1));
        let outline = single("box");
        for (name, px) in [
            ("legend", &legend),
            ("axes", &axes),
            ("scale", &scale),
            ("title", &title),
            ("box", &outline),
        ] {
            assert!(px.len() > 50, "{name} drew {} pixels", px.len());
        }
        let all = changed(
            &bare,
            &picture(
                "legend,axes,box,scale,title".parse().expect("all"),
                w,
                h,
                None,
                persp,
            ),
        );
        let mut union: Vec<usize> = [legend, axes, scale, title, outline].concat();
        union.sort_unstable();
        union.dedup();
        assert!(
            all.iter().all(|i| union.binary_search(i).is_ok()),
            "pixels outside every overlay changed"
        );
    }

    /// The box is hidden behind a surface in front of it and drawn where nothing is.
    #[test]
    fn the_outline_hides_behind_nearer_surfaces() {
        let (w, h) = (320u32, 240u32);
        let persp = Projection::Perspective { fov_deg: 35.0 };
        let just_box: Overlays = "box".parse().expect("box");
        let free = picture(just_box, w, h, None, persp);
        let far = vec![f32::INFINITY; (w * h) as usize];
        assert_eq!(picture(just_box, w, h, Some(&far), persp), free);
        // A surface at distance 1 covering the left half hides the box there.
        let wall: Vec<f32> = (0..w * h)
            .map(|i| if i % w < w / 2 { 1.0 } else { f32::INFINITY })
            .collect();
        let hidden = picture(just_box, w, h, Some(&wall), persp);
        let bare = picture(Overlays::NONE, w, h, None, persp);
        let left = |px: &[u8]| {
            changed(&bare, px)
                .iter()
                .filter(|&&i| (i as u32 % w) < w / 2 - 2)
                .count()
        };
        assert!(left(&free) > 50);
        assert_eq!(left(&hidden), 0);
        assert_eq!(
            changed(&bare, &hidden)
                .iter()
                .filter(|&&i| (i as u32 % w) > w / 2 + 2)
                .count(),
            changed(&bare, &free)
                .iter()
                .filter(|&&i| (i as u32 % w) > w / 2 + 2)
                .count()
        );
    }

    /// With the box overlay, each clip plane and slice is outlined along the polygon where
    /// it crosses the box, cut to what the clip planes keep; a plane beside the box adds
    /// nothing, and without the box overlay no plane is drawn.
    #[test]
    fn planes_are_outlined_where_they_cross_the_box() {
        let (w, h) = (640u32, 480u32);
        let persp = Projection::Perspective { fov_deg: 35.0 };
        let just_box: Overlays = "box".parse().expect("box");
        let plane = |s: &str| -> Plane { s.parse().expect("plane") };
        let slice = Slice::new(plane("x>0"));
        let bare = picture(Overlays::NONE, w, h, None, persp);
        let boxed = picture(just_box, w, h, None, persp);
        let sliced = with_planes(just_box, w, h, None, persp, &[], &[slice]);
        let added = changed(&boxed, &sliced);
        assert!(added.len() > 100, "the slice drew {} pixels", added.len());
        // Every pixel added lies by an edge of the square x = 0, |y|, |z| ≤ 0.5.
        let rays = camera(persp).ray_generator(w, h);
        let square = [
            [0.0, -0.5, -0.5],
            [0.0, 0.5, -0.5],
            [0.0, 0.5, 0.5],
            [0.0, -0.5, 0.5],
        ];
        let ends: Vec<(f64, f64)> = square
            .iter()
            .map(|&p| rays.project(p).map(|(x, y, _)| (x, y)).expect("in front"))
            .collect();
        let near_edge = |i: usize| {
            let (px, py) = ((i as u32 % w) as f64 + 0.5, (i as u32 / w) as f64 + 0.5);
            (0..4).any(|k| {
                let ((ax, ay), (bx, by)) = (ends[k], ends[(k + 1) % 4]);
                let (dx, dy) = (bx - ax, by - ay);
                let t = (((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
                (ax + t * dx - px).hypot(ay + t * dy - py) < 3.0
            })
        };
        assert!(added.iter().all(|&i| near_edge(i)), "pixels off the square");
        // A clip plane is outlined too; one beside the box is not.
        let clipped = with_planes(just_box, w, h, None, persp, &[plane("x<0.5")], &[]);
        assert!(changed(&boxed, &clipped).len() > 100);
        let beside = with_planes(just_box, w, h, None, persp, &[plane("x>5")], &[]);
        assert_eq!(beside, boxed);
        // A slice in the part a clip plane removes is not outlined.
        let keep_right = [plane("x>0.5")];
        assert_eq!(
            with_planes(just_box, w, h, None, persp, &keep_right, &[slice]),
            with_planes(just_box, w, h, None, persp, &keep_right, &[])
        );
        // Without the box overlay, nothing.
        let none = with_planes(Overlays::NONE, w, h, None, persp, &keep_right, &[slice]);
        assert_eq!(none, bare);
    }

    /// Sizes follow the picture: the legend's text is about as large relative to a 4K
    /// picture as to a 640×480 one.
    #[test]
    fn overlays_scale_with_the_picture() {
        let ortho = Projection::Orthographic { width: 4.0 };
        let legend: Overlays = "legend".parse().expect("legend");
        let extent = |w: u32, h: u32| {
            let bare = picture(Overlays::NONE, w, h, None, ortho);
            let px = changed(&bare, &picture(legend, w, h, None, ortho));
            let xs = px.iter().map(|&i| i as u32 % w);
            (xs.clone().max().unwrap_or(0) - xs.min().unwrap_or(0)) as f64 / f64::from(h)
        };
        let (small, large) = (extent(640, 480), extent(3840, 2160));
        assert!((small / large - 1.0).abs() < 0.25, "{small} vs {large}");
    }

    #[test]
    fn overlay_lists_parse_print_and_round_trip_in_json() {
        assert_eq!("none".parse::<Overlays>(), Ok(Overlays::NONE));
        let all: Overlays = "legend,axes,box,scale,title".parse().expect("all");
        assert!(all.legend && all.axes && all.outline && all.scale && all.title);
        let some: Overlays = "box, legend".parse().expect("two");
        assert_eq!(some.to_string(), "legend,box");
        assert_eq!(Overlays::default().to_string(), "legend,axes,box,scale");
        assert!("legend,axis".parse::<Overlays>().is_err());
        assert!("".parse::<Overlays>().is_err());
        let json = serde_json::to_string(&some).expect("json");
        assert_eq!(json, r#"["legend","box"]"#);
        assert_eq!(serde_json::from_str::<Overlays>(&json).expect("back"), some);
        assert_eq!(
            serde_json::from_str::<Overlays>("[]").expect("none"),
            Overlays::NONE
        );
        assert!(serde_json::from_str::<Overlays>(r#"["grid"]"#).is_err());
    }
}
