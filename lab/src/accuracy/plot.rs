//! The log–log chart of a report's errors against the finest cell width.

use super::*;

/// The relative RMS errors (stored Q, speed, vorticity and λ2, reconstructed Q, Q near
/// level boundaries, and the iso-surface position of `exact` hits in finest cells) against
/// the finest cell width, both axes logarithmic.
pub(crate) fn chart(report: &AccuracyReport) -> LogLogChart {
    type Pick = fn(&ResolutionReport) -> &ErrorStats;
    let series: [(&str, Pick, [u8; 3]); 7] = [
        ("stored Q", |r| &r.stored_q, [31, 119, 180]),
        ("stored speed", |r| &r.stored_speed, [255, 127, 14]),
        ("stored vorticity", |r| &r.stored_vorticity, [140, 86, 75]),
        ("stored lambda2", |r| &r.stored_lambda2, [227, 119, 194]),
        ("reconstructed Q", |r| &r.reconstructed_q, [44, 160, 44]),
        ("Q near level boundaries", |r| &r.boundary_q, [214, 39, 40]),
        (
            "iso-surface position (finest cells)",
            |r| &r.surface.position,
            [148, 103, 189],
        ),
    ];
    let mut res: Vec<&ResolutionReport> = report.resolutions.iter().collect();
    res.sort_by(|a, b| a.finest_width.total_cmp(&b.finest_width));
    let lines = series
        .into_iter()
        .map(|(name, pick, colour)| Line {
            name: name.to_string(),
            colour,
            points: res
                .iter()
                .filter(|r| pick(r).points > 0)
                .map(|r| (r.finest_width, pick(r).rms_rel))
                .collect(),
        })
        .collect();
    LogLogChart {
        title: format!("{} ({} stencil)", report.scene, report.stencil),
        x_desc: "finest cell width",
        y_desc: "RMS error / p99 |exact| (position: in finest cells)",
        x_label: |v| format!("{v:.3}"),
        lines,
        rings: Vec::new(),
        empty_range: [(0.01, 0.1), (1e-3, 1e-1)],
        pad: 1.5,
    }
}

/// Writes [`chart`] to `path` atomically, 800×560 pixels.
pub fn save_plot(path: &std::path::Path, report: &AccuracyReport) -> Result<(), PlotError> {
    chart(report).save(path, (800, 560))
}
