//! Field values and the gradient of one field at given points (`qbricks-view probe`).

use crate::volume::Volume;

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
        .map(|&p| match vol.sample(p, grad_field) {
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
        })
        .collect()
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
pub fn parse_points_csv(text: &str) -> Result<Vec<[f64; 3]>, String> {
    let mut out = Vec::new();
    let mut first = true;
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        if std::mem::take(&mut first) && is_header(line) {
            continue;
        }
        out.push(parse_xyz(line).map_err(|e| format!("line {}: {e}", i + 1))?);
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

/// Parses `x,y,z`.
pub(crate) fn parse_xyz(s: &str) -> Result<[f64; 3], String> {
    let nums: Vec<&str> = s.split(',').map(str::trim).collect();
    if nums.len() != 3 {
        return Err(format!("expected x,y,z, found `{s}`"));
    }
    let mut p = [0.0; 3];
    for (a, n) in nums.iter().enumerate() {
        p[a] = n
            .parse::<f64>()
            .map_err(|_| format!("expected a number, found `{n}` in `{s}`"))?;
        if !p[a].is_finite() {
            return Err(format!("expected a finite number, found `{n}`"));
        }
    }
    Ok(p)
}

/// Largest number of points of a `--line`.
pub(crate) const MAX_LINE_POINTS: usize = 10_000_000;

/// Parses `x0,y0,z0:x1,y1,z1:N` into `N` evenly spaced points from start to end inclusive.
pub fn parse_line(s: &str) -> Result<Vec<[f64; 3]>, String> {
    let parts: Vec<&str> = s.split(':').collect();
    let [a, b, n] = parts[..] else {
        return Err(format!("expected x0,y0,z0:x1,y1,z1:N, found `{s}`"));
    };
    let (a, b) = (parse_xyz(a)?, parse_xyz(b)?);
    let n: usize = n
        .trim()
        .parse()
        .map_err(|_| format!("expected a point count N, found `{n}`"))?;
    if n == 0 || n > MAX_LINE_POINTS {
        return Err(format!("expected 1..={MAX_LINE_POINTS} points, found {n}"));
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
    if let Some(p) = points.iter().find(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(format!(
            "a point of the line is not finite ({p:?}): ends too close to the largest f64"
        ));
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
            assert!(e.starts_with("line 1: "), "{bad}: {e}");
        }
        // Blank lines before the header do not make it a data line; a second header is.
        assert_eq!(
            parse_points_csv("\n\nx,y,z\n4,5,6\n").expect("blank lines"),
            vec![[4.0, 5.0, 6.0]]
        );
        let e = parse_points_csv("x,y,z\nx,y,z\n").expect_err("two headers");
        assert!(e.starts_with("line 2: "), "{e}");
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
        assert!(parse_line("nan,0,0:1,0,0:2").is_err());
        assert!(parse_line("1e309,0,0:1,0,0:2").is_err());
    }
}
