//! The status line under the image: what is shown, of which file, and the picked point.

use super::document::Doc;
use super::picking::PickInfo;
use crate::progressive::{Level, Update};

/// The status line: the image `shown`, the open `doc`, the `pick`ed point, what the
/// window is `busy` with beside rendering (opening a file, framing the surface).
pub(crate) fn status_text(
    shown: Option<&Update>,
    doc: Option<&Doc>,
    pick: Option<&PickInfo>,
    busy: Option<&str>,
) -> String {
    let mut parts = Vec::new();
    if let Some(b) = busy {
        parts.push(b.to_string());
    }
    match shown {
        Some(u) => {
            let rays = u.counts.rays.max(1) as f64;
            let level = match u.level {
                Level::Preview { scale } => format!("preview 1/{scale}"),
                Level::Full if u.complete => format!("full, {} spp", u.samples),
                Level::Full => format!("full, {}/{} spp", u.samples, u.spp),
            };
            parts.push(format!(
                "{:.1} ms · {level} · {}×{} · {:.2} samples/ray · {:.2} Mrays/s",
                u.ms,
                u.width,
                u.height,
                u.counts.stats.samples as f64 / rays,
                u.counts.rays as f64 / (u.ms.max(1e-3) * 1e3),
            ));
        }
        None => parts.push("no image yet".to_string()),
    }
    if let Some(doc) = doc {
        parts.push(format!(
            "{} cells · {} bricks · {} regions",
            doc.cells, doc.bricks, doc.regions
        ));
    }
    if let Some(p) = pick {
        let vals: Vec<String> = p
            .values
            .iter()
            .map(|(n, v)| format!("{n} {v:.4}"))
            .collect();
        parts.push(format!(
            "at ({:.3}, {:.3}, {:.3}): {}",
            p.world[0],
            p.world[1],
            p.world[2],
            if vals.is_empty() {
                "outside the data".to_string()
            } else {
                vals.join(", ")
            }
        ));
    }
    parts.join("  |  ")
}
