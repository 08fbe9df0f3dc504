//! Log–log line charts as PNG bytes. `qbricks-lab accuracy --plot` (errors against the
//! cell width) and `qbricks-lab bench --plot` (errors against the time per frame) draw the
//! same kind of chart, so both go through this one set-up: white background, caption,
//! logarithmic axes with some room around the points, one line with dots per series, a
//! legend, and a font embedded from a crate so no system fonts are needed.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use image::ImageEncoder as _;
use plotters::prelude::*;

/// Name under which the embedded font is registered with plotters.
const FONT: &str = "qbricks-plot";

/// What plotters' bitmap drawing fails with.
pub(crate) type DrawError =
    DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>;

/// One series: a named line through its points, in the order given.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    pub name: String,
    pub colour: [u8; 3],
    pub points: Vec<(f64, f64)>,
}

/// A chart with both axes logarithmic. Only points with both coordinates positive and
/// finite are drawn (a log axis has no place for the others); the axes span those points
/// times and divided by `pad`, or `empty_range` when there are none.
#[derive(Debug, Clone)]
pub struct LogLogChart {
    pub title: String,
    pub x_desc: &'static str,
    pub y_desc: &'static str,
    /// Text of an x-axis label (the y labels are in `1e-3` form).
    pub x_label: fn(&f64) -> String,
    pub lines: Vec<Line>,
    /// Points circled in black on top of the lines (a benchmark's default setting).
    pub rings: Vec<(f64, f64)>,
    /// `[x range, y range]` without any point to draw.
    pub empty_range: [(f64, f64); 2],
    pub pad: f64,
}

/// Why a chart could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum ChartError {
    #[error("embedded plot font is not a valid TTF")]
    Font,
    #[error("{0}")]
    Draw(DrawError),
    #[error("{0}")]
    Png(image::ImageError),
}

/// Why a chart could not be written to its file.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("{}: {error}", path.display())]
    Chart { path: PathBuf, error: ChartError },
    #[error("{}: {error}", path.display())]
    Write {
        path: PathBuf,
        error: std::io::Error,
    },
}

fn drawable(p: &(f64, f64)) -> bool {
    let ok = |v: f64| v > 0.0 && v.is_finite();
    ok(p.0) && ok(p.1)
}

impl LogLogChart {
    /// PNG bytes of the chart, `size` pixels.
    pub(crate) fn png(&self, size: (u32, u32)) -> Result<Vec<u8>, ChartError> {
        // Registering twice only replaces the same font.
        plotters::style::register_font(FONT, FontStyle::Normal, epaint_default_fonts::UBUNTU_LIGHT)
            .map_err(|_| ChartError::Font)?;
        let lines: Vec<(&Line, Vec<(f64, f64)>)> = self
            .lines
            .iter()
            .map(|l| {
                (
                    l,
                    l.points
                        .iter()
                        .copied()
                        .filter(drawable)
                        .collect::<Vec<_>>(),
                )
            })
            .filter(|(_, pts)| !pts.is_empty())
            .collect();
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, y) in lines.iter().flat_map(|(_, pts)| pts) {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if lines.is_empty() {
            let [(a, b), (c, d)] = self.empty_range;
            (x0, x1, y0, y1) = (a, b, c, d);
        }
        let pad = self.pad;
        let (x0, x1, y0, y1) = (x0 / pad, x1 * pad, y0 / pad, y1 * pad);
        let (w, h) = size;
        let mut buf = vec![255u8; w as usize * h as usize * 3];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            root.fill(&WHITE).map_err(ChartError::Draw)?;
            let mut chart = ChartBuilder::on(&root)
                .caption(&self.title, (FONT, 18))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
                .map_err(ChartError::Draw)?;
            chart
                .configure_mesh()
                .x_desc(self.x_desc)
                .y_desc(self.y_desc)
                .x_label_formatter(&self.x_label)
                .y_label_formatter(&|v| format!("{v:.0e}"))
                .label_style((FONT, 13))
                .draw()
                .map_err(ChartError::Draw)?;
            for (line, pts) in &lines {
                let [r, g, b] = line.colour;
                let colour = RGBColor(r, g, b);
                chart
                    .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                    .map_err(ChartError::Draw)?
                    .label(line.name.as_str())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                    });
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                    .map_err(ChartError::Draw)?;
            }
            chart
                .draw_series(
                    self.rings
                        .iter()
                        .filter(|p| drawable(p))
                        .map(|&p| Circle::new(p, 8, BLACK.stroke_width(2))),
                )
                .map_err(ChartError::Draw)?;
            chart
                .configure_series_labels()
                .label_font((FONT, 13))
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(ChartError::Draw)?;
            root.present().map_err(ChartError::Draw)?;
        }
        let mut out = Vec::new();
        image::codecs::png::PngEncoder::new(&mut out)
            .write_image(&buf, w, h, image::ExtendedColorType::Rgb8)
            .map_err(ChartError::Png)?;
        Ok(out)
    }

    /// Writes [`LogLogChart::png`] to `path` atomically.
    pub fn save(&self, path: &Path, size: (u32, u32)) -> Result<(), PlotError> {
        let bytes = self.png(size).map_err(|error| PlotError::Chart {
            path: path.to_path_buf(),
            error,
        })?;
        files::output::write_atomic(path, |f| f.write_all(&bytes)).map_err(|error| {
            PlotError::Write {
                path: path.to_path_buf(),
                error,
            }
        })
    }
}
