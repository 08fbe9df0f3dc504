//! The film: per-pixel sums of ray colours, filled tile by tile and sample wave by
//! sample wave, resolved to an image; and images to PNG files, written atomically with
//! `files::output::write_atomic`, so a reader never sees a partial PNG.
//!
//! Sums are kept in `f64` and every pixel adds its samples in sample order, so an image
//! accumulated over several waves is bit-identical to one rendered in a single pass.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::tiles::{Tile, TileResult};

/// Bytes a headless frame holds per pixel: the film's f64 sums and sample counts (28), its
/// depth and surface values, twice (16), the resolved f32 image (12), the 8-bit copy and
/// the PNG encoder's buffer (≈ 6), rounded up.
pub const FRAME_BYTES_PER_PIXEL: u64 = 64;
/// Most bytes the frames of one request may take (about 13 000² pixels for one frame),
/// whatever the machine.
pub const MAX_FRAME_BYTES: u64 = 8 << 30;

/// Refuses `frames` images of `width`×`height` held at once (a render holds one, `bench` its
/// reference and the run being measured) when they need more than [`MAX_FRAME_BYTES`] or
/// the memory limit, before any of it is allocated (a 16384² image takes about 12 GiB).
pub fn check_frame_memory(
    width: u32,
    height: u32,
    frames: u64,
) -> Result<(), files::limits::LimitError> {
    let need = u64::from(width)
        .saturating_mul(u64::from(height))
        .saturating_mul(FRAME_BYTES_PER_PIXEL)
        .saturating_mul(frames);
    let what = if frames == 1 {
        format!("a {width}x{height} image")
    } else {
        format!("a {width}x{height} image ({frames} copies)")
    };
    files::limits::check_memory_capped(what, need, MAX_FRAME_BYTES, "8 GiB for images")
}

/// A pixel's colour: the sum of its `samples` (> 0) sample colours over their count.
#[inline]
pub(crate) fn mean_colour(sum: [f64; 3], samples: u32) -> [f32; 3] {
    sum.map(|c| (c / f64::from(samples)) as f32)
}

/// Accumulated samples of a `width`×`height` image.
#[derive(Debug, Clone)]
pub(crate) struct Film {
    pub width: u32,
    pub height: u32,
    colours: Colours,
    /// Samples whose ray hit the surface (iso) or gathered opacity (dvr), per pixel.
    hits: Vec<u32>,
    /// What sample 0 of each pixel met first: its distance (infinite before sample 0 and
    /// where nothing was met) and the colour field's value there.
    depth: Vec<f32>,
    values: Vec<f32>,
}

/// How a film holds its colours.
#[derive(Debug, Clone)]
enum Colours {
    /// Per pixel the sum of its samples' colours and their count: samples arrive in
    /// several waves (the window's accumulation).
    Waves {
        sum: Vec<[f64; 3]>,
        samples: Vec<u32>,
    },
    /// Per pixel its mean colour, written once: every sample of a pixel arrives in one
    /// tile (a frame rendered in one pass). It holds the same numbers as `Waves` would
    /// resolve to, in half the memory a frame touches, and hands them over without a copy.
    OnePass { rgb: Vec<[f32; 3]> },
}

/// A finished film's per-pixel buffers (row-major), as a [`crate::render::Frame`] holds them.
pub(crate) struct FilmParts {
    pub rgb: Vec<[f32; 3]>,
    pub hits: Vec<u32>,
    pub depth: Vec<f32>,
    pub values: Vec<f32>,
}

impl Film {
    /// A film for samples added in any number of waves.
    pub(crate) fn new(width: u32, height: u32) -> Film {
        let n = width as usize * height as usize;
        Film::with(
            width,
            height,
            Colours::Waves {
                sum: vec![[0.0; 3]; n],
                samples: vec![0; n],
            },
        )
    }

    /// A film each of whose pixels is added at most once (one tile result holding all its
    /// samples): a frame rendered in one pass.
    pub(crate) fn one_pass(width: u32, height: u32) -> Film {
        let n = width as usize * height as usize;
        Film::with(
            width,
            height,
            Colours::OnePass {
                rgb: vec![[0.0; 3]; n],
            },
        )
    }

    fn with(width: u32, height: u32, colours: Colours) -> Film {
        let n = width as usize * height as usize;
        Film {
            width,
            height,
            colours,
            hits: vec![0; n],
            depth: vec![f32::INFINITY; n],
            values: vec![f32::NAN; n],
        }
    }

    /// Adds a rendered tile (its pixels' sums over its sample range).
    pub(crate) fn add(&mut self, r: &TileResult) {
        let Tile { x0, y0, x1, y1 } = r.tile;
        let n = r.samples.len() as u32;
        let tw = (x1 - x0) as usize;
        for y in y0..y1.min(self.height) {
            for x in x0..x1.min(self.width) {
                let i = (y * self.width + x) as usize;
                let j = (y - y0) as usize * tw + (x - x0) as usize;
                let c = r.sum[j];
                if let Some(f) = r.first.get(j) {
                    self.depth[i] = f.t;
                    self.values[i] = f.value;
                }
                match &mut self.colours {
                    Colours::Waves { sum, samples } => {
                        for a in 0..3 {
                            sum[i][a] += c[a];
                        }
                        samples[i] += n;
                    }
                    Colours::OnePass { rgb } => {
                        if n > 0 {
                            // `0.0 +` as a sum that starts at zero adds it (-0.0 becomes 0.0).
                            rgb[i] = mean_colour(c.map(|v| 0.0 + v), n);
                        }
                    }
                }
                self.hits[i] += r.hit_samples.get(j).copied().unwrap_or(0);
            }
        }
    }

    /// Per pixel (row-major), the distance to the first surface sample 0 met.
    pub(crate) fn depth(&self) -> &[f32] {
        &self.depth
    }

    /// Per pixel (row-major), the colour field's value where sample 0 met the surface.
    pub(crate) fn surface_values(&self) -> &[f32] {
        &self.values
    }

    /// Mean colour of pixel `i` (row-major), `None` before its first sample.
    #[inline]
    pub(crate) fn pixel(&self, i: usize) -> Option<[f32; 3]> {
        match &self.colours {
            Colours::Waves { sum, samples } => {
                let n = samples[i];
                (n > 0).then(|| mean_colour(sum[i], n))
            }
            Colours::OnePass { rgb } => Some(rgb[i]),
        }
    }

    /// The image: each pixel's mean over its samples (black where none yet).
    pub(crate) fn resolve(&self) -> Vec<[f32; 3]> {
        match &self.colours {
            Colours::Waves { sum, .. } => (0..sum.len())
                .map(|i| self.pixel(i).unwrap_or([0.0; 3]))
                .collect(),
            Colours::OnePass { rgb } => rgb.clone(),
        }
    }

    /// The resolved image and the per-pixel buffers, moved out of the film.
    pub(crate) fn into_parts(self) -> FilmParts {
        let rgb = match self.colours {
            Colours::OnePass { rgb } => rgb,
            Colours::Waves { .. } => self.resolve(),
        };
        FilmParts {
            rgb,
            hits: self.hits,
            depth: self.depth,
            values: self.values,
        }
    }
}

/// Why a PNG could not be written: the file, and whether encoding or writing failed.
#[derive(Debug, thiserror::Error)]
pub enum FilmError {
    #[error("{}: {error}", path.display())]
    Encode { path: PathBuf, error: EncodeError },
    #[error("{}: {error}", path.display())]
    Write {
        path: PathBuf,
        error: std::io::Error,
    },
}

/// Why pixels could not be encoded as a PNG.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    #[error("expected {} pixels for {width}x{height}, found {found}", *width as usize * *height as usize)]
    PixelCount {
        width: u32,
        height: u32,
        found: usize,
    },
    #[error("{0}")]
    Png(image::ImageError),
}

/// 8-bit RGB bytes of an image of linear values in 0..=1 (clamped, rounded).
pub fn to_rgb8(rgb: &[[f32; 3]]) -> Vec<u8> {
    rgb.iter()
        .flat_map(|c| c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
        .collect()
}

/// PNG bytes of a `width`×`height` image.
pub fn encode_png(width: u32, height: u32, rgb: &[[f32; 3]]) -> Result<Vec<u8>, EncodeError> {
    if rgb.len() != width as usize * height as usize {
        return Err(EncodeError::PixelCount {
            width,
            height,
            found: rgb.len(),
        });
    }
    encode_png_rgb8(width, height, to_rgb8(rgb))
}

/// PNG bytes of a `width`×`height` image of 8-bit RGB pixels (a picture with its
/// overlays, [`crate::overlay::picture`]).
pub fn encode_png_rgb8(width: u32, height: u32, rgb8: Vec<u8>) -> Result<Vec<u8>, EncodeError> {
    let found = rgb8.len() / 3;
    let img = image::RgbImage::from_raw(width, height, rgb8).ok_or(EncodeError::PixelCount {
        width,
        height,
        found,
    })?;
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(EncodeError::Png)?;
    Ok(out.into_inner())
}

/// Writes the image as a PNG at `path`, atomically.
pub fn save_png(path: &Path, width: u32, height: u32, rgb: &[[f32; 3]]) -> Result<(), FilmError> {
    write_png(path, encode_png(width, height, rgb))
}

/// Writes a picture of 8-bit RGB pixels as a PNG at `path`, atomically.
pub fn save_png_rgb8(path: &Path, width: u32, height: u32, rgb8: Vec<u8>) -> Result<(), FilmError> {
    write_png(path, encode_png_rgb8(width, height, rgb8))
}

fn write_png(path: &Path, bytes: Result<Vec<u8>, EncodeError>) -> Result<(), FilmError> {
    let bytes = bytes.map_err(|error| FilmError::Encode {
        path: path.to_path_buf(),
        error,
    })?;
    files::output::write_atomic(path, |f| f.write_all(&bytes)).map_err(|error| FilmError::Write {
        path: path.to_path_buf(),
        error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ray::FirstSurface;
    use crate::sampling::Stats;

    /// A tile of `samples` over pixels `[x0, x1) × [y0, y1)` whose colours, hits and first
    /// surfaces follow from the pixel, with negative zeros, tiny and large sums among them.
    fn tile(x0: u32, y0: u32, x1: u32, y1: u32, samples: std::ops::Range<u32>) -> TileResult {
        let mut r = TileResult {
            tile: Tile { x0, y0, x1, y1 },
            samples: samples.clone(),
            sum: Vec::new(),
            hit_samples: Vec::new(),
            first: Vec::new(),
            stats: Stats::default(),
            rays: 0,
            hits: 0,
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let k = f64::from(x * 7 + y * 13 + samples.start);
                r.sum.push([-0.0, (k * 0.37).sin() * 1e-300, k / 3.0]);
                r.hit_samples.push((x + y) % (samples.len() as u32 + 1));
                if samples.start == 0 {
                    r.first.push(FirstSurface {
                        t: k as f32,
                        value: -(k as f32),
                    });
                }
            }
        }
        r
    }

    /// A frame filled in one pass (its mean written per pixel) hands over the same bits as
    /// the same samples summed in one wave and resolved, and as a film of two waves whose
    /// second adds nothing but zeros; pixels no tile reached are black, with no hits, an
    /// infinite depth and a NaN value, in both.
    #[test]
    fn one_pass_films_resolve_to_the_bits_of_summed_ones() {
        let (w, h) = (37, 21);
        let tiles = [
            tile(0, 0, 16, 16, 0..3),
            tile(16, 0, 37, 16, 0..3),
            tile(0, 16, 30, 21, 0..3),
        ];
        let mut once = Film::one_pass(w, h);
        let mut waves = Film::new(w, h);
        for t in &tiles {
            once.add(t);
            waves.add(t);
        }
        let bits = |p: FilmParts| {
            (
                p.rgb
                    .iter()
                    .flatten()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>(),
                p.hits,
                p.depth.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                p.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        assert_eq!(once.pixel(0), waves.pixel(0));
        assert_eq!(once.resolve(), waves.resolve());
        let (a, b) = (bits(once.into_parts()), bits(waves.into_parts()));
        assert_eq!(a, b);
        // A pixel of the untouched corner (x ≥ 30, y ≥ 16), and a reached one.
        let i = 20 * w as usize + 33;
        assert_eq!((a.0[3 * i..3 * i + 3].to_vec(), a.1[i]), (vec![0; 3], 0));
        assert_eq!(f32::from_bits(a.2[i]), f32::INFINITY);
        assert!(f32::from_bits(a.3[i]).is_nan());
        assert!(a.0.iter().any(|&v| f32::from_bits(v) > 1.0));
        // The negative zeros of the sums are positive zeros, as a sum from zero makes them.
        assert_eq!(a.0[0], 0.0f32.to_bits());
    }
}
