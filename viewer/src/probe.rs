//! Field values and the gradient of one field at given points (`qbricks-view probe`), and
//! every field on a plane sampled on a regular grid ([`plane`], written by [`plane_file`]).

use crate::volume::Volume;

pub mod plane;
pub mod plane_file;

/// One probed point: every field (NaN outside the data), the exact gradient of the
/// reconstruction of the chosen field, and the unit shading normal the renderer uses
/// there (from [`Volume::shading_gradient`], smooth across cell faces; NaN outside).
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    pub p: [f64; 3],
    pub values: Vec<f64>,
    pub gradient: [f64; 3],
    pub normal: [f64; 3],
}

/// Probes every point (world coordinates).
pub fn probe(vol: &Volume, points: &[[f64; 3]], grad_field: usize) -> Vec<Probe> {
    points
        .iter()
        .map(|&p| probe_one(vol, p, grad_field))
        .collect()
}

fn probe_one(vol: &Volume, p: [f64; 3], grad_field: usize) -> Probe {
    match vol.sample(p, grad_field) {
        Some(s) => Probe {
            p,
            values: s.values.iter().map(|&v| v as f64).collect(),
            gradient: s.gradient,
            normal: vol
                .shading_gradient(vol.to_local(p), grad_field)
                .and_then(|g| glam::DVec3::from_array(g).try_normalize())
                .map_or([f64::NAN; 3], |n| n.to_array()),
        },
        None => Probe {
            p,
            values: vec![f64::NAN; vol.fields.len()],
            gradient: [f64::NAN; 3],
            normal: [f64::NAN; 3],
        },
    }
}

/// Points probed and written at a time: the report streams, so its memory stays bounded
/// (a few MiB) whatever the number of points; each chunk is probed on all cores.
const CHUNK: usize = 1 << 14;

/// How [`write_report`] prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReportFormat {
    /// A header line, then `x,y,z,<fields>,d<f>/dx,…,normal_x,…` per point (NaN outside).
    Csv,
    /// A JSON list of `{x, y, z, <field>…, gradient, normal}` (null outside: JSON has no
    /// NaN).
    Json,
}

/// Probes `points` and writes the report to `out` chunk by chunk (see [`CHUNK`]).
pub fn write_report(
    out: &mut impl std::io::Write,
    vol: &Volume,
    points: &[[f64; 3]],
    grad_field: usize,
    format: ReportFormat,
) -> std::io::Result<()> {
    use rayon::prelude::*;
    if format == ReportFormat::Csv {
        let names: Vec<&str> = vol.fields.iter().map(|f| f.name.as_str()).collect();
        let g = vol.fields.get(grad_field).map_or("", |f| f.name.as_str());
        writeln!(
            out,
            "x,y,z,{},d{g}/dx,d{g}/dy,d{g}/dz,normal_x,normal_y,normal_z",
            names.join(",")
        )?;
    } else {
        write!(out, "[")?;
    }
    for (c, chunk) in points.chunks(CHUNK).enumerate() {
        let probed: Vec<Probe> = chunk
            .par_iter()
            .map(|&p| probe_one(vol, p, grad_field))
            .collect();
        for (i, r) in probed.iter().enumerate() {
            match format {
                ReportFormat::Csv => write_csv_row(out, r)?,
                ReportFormat::Json => {
                    if c + i > 0 {
                        write!(out, ",")?;
                    }
                    serde_json::to_writer(&mut *out, &json_object(vol, r))?;
                }
            }
        }
    }
    if format == ReportFormat::Json {
        writeln!(out, "]")?;
    }
    Ok(())
}

fn write_csv_row(out: &mut impl std::io::Write, r: &Probe) -> std::io::Result<()> {
    let vals: Vec<String> = r.values.iter().map(|v| v.to_string()).collect();
    writeln!(
        out,
        "{},{},{},{},{},{},{},{},{},{}",
        r.p[0],
        r.p[1],
        r.p[2],
        vals.join(","),
        r.gradient[0],
        r.gradient[1],
        r.gradient[2],
        r.normal[0],
        r.normal[1],
        r.normal[2]
    )
}

/// One point as a JSON object (keys sorted, as `serde_json` maps are).
fn json_object(vol: &Volume, r: &Probe) -> serde_json::Value {
    let num = |v: f64| {
        serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, serde_json::Value::Number)
    };
    let mut o = serde_json::Map::new();
    o.insert("x".into(), num(r.p[0]));
    o.insert("y".into(), num(r.p[1]));
    o.insert("z".into(), num(r.p[2]));
    for (f, v) in vol.fields.iter().zip(&r.values) {
        o.insert(f.name.clone(), num(*v));
    }
    o.insert(
        "gradient".into(),
        serde_json::Value::Array(r.gradient.iter().map(|&g| num(g)).collect()),
    );
    o.insert(
        "normal".into(),
        serde_json::Value::Array(r.normal.iter().map(|&g| num(g)).collect()),
    );
    serde_json::Value::Object(o)
}

/// The field whose gradient is reported by default: `q` if present, else the first.
pub fn default_field(vol: &Volume) -> usize {
    vol.fields.iter().position(|f| f.name == "q").unwrap_or(0)
}

/// Parses `x,y,z` per line; blank lines are skipped, and the first non-blank line may be a
/// header. Errors name the line.
///
/// Only a line of three column names (see [`is_header`]) is a header: a malformed first
/// data line (`0,0`, `nan,0,0`, `0;0;0`, `0x1,0,0`) is an error like any other line, so a
/// typo cannot silently drop the only point, or every point after a mistaken header.
pub fn parse_points_csv(text: &str) -> Result<Vec<[f64; 3]>, PointsCsvError> {
    // Room for one point per line, reserved within the memory limit, so a huge list is
    // refused up front (naming its size) instead of aborting while it grows.
    let lines = text.bytes().filter(|&b| b == b'\n').count() + 1;
    let mut out = files::limits::with_capacity(format!("{lines} points"), lines).map_err(|e| {
        PointsCsvError {
            line: 0,
            error: PointError::TooMany(e),
        }
    })?;
    let mut first = true;
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        if std::mem::take(&mut first) && is_header(line) {
            continue;
        }
        out.push(parse_xyz(line).map_err(|error| PointsCsvError { line: i + 1, error })?);
    }
    Ok(out)
}

/// Whether `line` is a header: exactly three comma-separated column names, each starting
/// with a letter or `_` and made of letters, digits, `_`, `-`, `.`, spaces or brackets
/// (`x,y,z`, `X [m], Y [m], Z [m]`), none of them a number `f64` would parse (`nan`, `inf`).
pub(crate) fn is_header(line: &str) -> bool {
    let names: Vec<&str> = line.split(',').map(str::trim).collect();
    names.len() == 3
        && names.iter().all(|n| {
            n.starts_with(|c: char| c.is_alphabetic() || c == '_')
                && n.chars()
                    .all(|c| c.is_alphanumeric() || "_-. []()".contains(c))
                && n.parse::<f64>().is_err()
        })
}

/// Why a line of a points CSV is refused: its 1-based number (0: the list as a whole) and
/// the point's error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{error}", if *line == 0 { String::new() } else { format!("line {line}: ") })]
pub struct PointsCsvError {
    pub line: usize,
    pub error: PointError,
}

/// Why `x,y,z` is not a point.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PointError {
    #[error("expected x,y,z, found `{text}`")]
    NotThree { text: String },
    #[error("expected a number, found `{number}` in `{text}`")]
    NotNumber { number: String, text: String },
    #[error("expected a finite number, found `{number}`")]
    NotFinite { number: String },
    /// The list as a whole does not fit in memory.
    #[error("{0}")]
    TooMany(files::limits::LimitError),
}

/// Parses `x,y,z`.
pub(crate) fn parse_xyz(s: &str) -> Result<[f64; 3], PointError> {
    let nums: Vec<&str> = s.split(',').map(str::trim).collect();
    if nums.len() != 3 {
        return Err(PointError::NotThree {
            text: s.to_string(),
        });
    }
    let mut p = [0.0; 3];
    for (a, n) in nums.iter().enumerate() {
        p[a] = n.parse::<f64>().map_err(|_| PointError::NotNumber {
            number: n.to_string(),
            text: s.to_string(),
        })?;
        if !p[a].is_finite() {
            return Err(PointError::NotFinite {
                number: n.to_string(),
            });
        }
    }
    Ok(p)
}

/// Why a `--line` is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LineError {
    #[error("expected x0,y0,z0:x1,y1,z1:N, found `{text}`")]
    Form { text: String },
    /// One of the two ends.
    #[error("{0}")]
    End(PointError),
    #[error("expected a point count N, found `{count}`")]
    NotCount { count: String },
    #[error("expected 1..={MAX_LINE_POINTS} points, found {count}")]
    Count { count: usize },
    /// Ends so far apart that points between them overflow.
    #[error("a point of the line is not finite ({point:?}): ends too close to the largest f64")]
    NotFinite { point: [f64; 3] },
}

/// Largest number of points of a `--line`.
pub(crate) const MAX_LINE_POINTS: usize = 10_000_000;

/// Parses `x0,y0,z0:x1,y1,z1:N` into `N` evenly spaced points from start to end inclusive.
pub fn parse_line(s: &str) -> Result<Vec<[f64; 3]>, LineError> {
    let parts: Vec<&str> = s.split(':').collect();
    let [a, b, n] = parts[..] else {
        return Err(LineError::Form {
            text: s.to_string(),
        });
    };
    let (a, b) = (
        parse_xyz(a).map_err(LineError::End)?,
        parse_xyz(b).map_err(LineError::End)?,
    );
    let n: usize = n.trim().parse().map_err(|_| LineError::NotCount {
        count: n.to_string(),
    })?;
    if n == 0 || n > MAX_LINE_POINTS {
        return Err(LineError::Count { count: n });
    }
    // `a + s (b - a)` overflows when `b - a` does (`-1e308 → 1e308`); the weighted sum of
    // two finite ends stays within them up to rounding, and is exact at both ends.
    let points: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            let s = if n == 1 {
                0.0
            } else {
                i as f64 / (n - 1) as f64
            };
            std::array::from_fn(|k| (1.0 - s) * a[k] + s * b[k])
        })
        .collect();
    if let Some(&point) = points.iter().find(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(LineError::NotFinite { point });
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_line_of_column_names_is_a_header() {
        for header in ["x,y,z", "X [m], Y [m], Z [m]", "_a,b1,pos.z"] {
            let pts = parse_points_csv(&format!("{header}\n1,2,3\n")).expect(header);
            assert_eq!(pts, vec![[1.0, 2.0, 3.0]], "{header}");
        }
        // Malformed first lines are errors naming line 1, not skipped as a header.
        for bad in [
            "0,0",
            "0,0,0,0",
            "nan,0,0",
            "1e309,0,0",
            "0;0;0",
            "0 0 0",
            "0x1,0,0",
            "x,y",
            "inf,y,z",
            "x,y,z,w",
        ] {
            let e = parse_points_csv(&format!("{bad}\n1,2,3\n")).expect_err(bad);
            assert_eq!(e.line, 1, "{bad}: {e}");
        }
        // Blank lines before the header do not make it a data line; a second header is.
        assert_eq!(
            parse_points_csv("\n\nx,y,z\n4,5,6\n").expect("blank lines"),
            vec![[4.0, 5.0, 6.0]]
        );
        let e = parse_points_csv("x,y,z\nx,y,z\n").expect_err("two headers");
        assert_eq!(e.line, 2, "{e}");
        assert_eq!(
            e.to_string(),
            "line 2: expected a number, found `x` in `x,y,z`"
        );
    }

    #[test]
    fn line_points_stay_finite_and_hit_both_ends_exactly() {
        let pts = parse_line("-1e308,0,0:1e308,0,0:3").expect("huge but finite ends");
        assert_eq!(
            pts,
            vec![[-1e308, 0.0, 0.0], [0.0, 0.0, 0.0], [1e308, 0.0, 0.0]]
        );
        let pts = parse_line("0.1,0.2,0.3:0.7,-0.9,1.1:7").expect("line");
        assert_eq!(pts[0], [0.1, 0.2, 0.3]);
        assert_eq!(pts[6], [0.7, -0.9, 1.1]);
        assert!(matches!(
            parse_line("nan,0,0:1,0,0:2"),
            Err(LineError::End(PointError::NotFinite { .. }))
        ));
        assert!(matches!(
            parse_line("1e309,0,0:1,0,0:2"),
            Err(LineError::End(PointError::NotFinite { .. }))
        ));
    }
}
