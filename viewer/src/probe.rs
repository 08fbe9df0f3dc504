//! Field values and the gradient of one field at given points (`qbricks-view probe`).

use crate::volume::Volume;

/// One probed point: every field (NaN outside the data) and the gradient of the chosen
/// field (NaN outside).
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    pub p: [f64; 3],
    pub values: Vec<f64>,
    pub gradient: [f64; 3],
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
            },
            None => Probe {
                p,
                values: vec![f64::NAN; vol.fields.len()],
                gradient: [f64::NAN; 3],
            },
        })
        .collect()
}

/// The field whose gradient is reported by default: `q` if present, else the first.
pub fn default_field(vol: &Volume) -> usize {
    vol.fields.iter().position(|f| f.name == "q").unwrap_or(0)
}

/// Parses `x,y,z` per line, with an optional header line (any first line that does not
/// parse as three numbers); blank lines are skipped. Errors name the line.
pub fn parse_points_csv(text: &str) -> Result<Vec<[f64; 3]>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        match parse_xyz(line) {
            Ok(p) => out.push(p),
            Err(_) if i == 0 => {} // header
            Err(e) => return Err(format!("line {}: {e}", i + 1)),
        }
    }
    Ok(out)
}

/// Parses `x,y,z`.
pub fn parse_xyz(s: &str) -> Result<[f64; 3], String> {
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
pub const MAX_LINE_POINTS: usize = 10_000_000;

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
    Ok((0..n)
        .map(|i| {
            let s = if n == 1 {
                0.0
            } else {
                i as f64 / (n - 1) as f64
            };
            std::array::from_fn(|k| a[k] + s * (b[k] - a[k]))
        })
        .collect())
}
