//! A sampled plane ([`PlaneSamples`]) as a file: CSV, JSON or NumPy `.npy`, written to any
//! `Write` (the command puts it in place through `files::output`).
//!
//! - CSV: a header `i,j,x,y,z,<field>…`, then one line per sample, `j` the slow index
//!   (row `j = 0` first, `i` from 0 in each row); NaN outside the data. Numbers are printed
//!   as `probe`'s report prints them (each value the `f32` reconstruction widened to `f64`,
//!   the shortest text that reads back to it), so a sample and `probe --points` at its
//!   `x,y,z` print the same text.
//! - JSON: one object: `origin`, `u`, `v`, `resolution` `[NU, NV]`, `samples_at` (the
//!   sample-position rule in words), `fields` (their order), `outside` (the count of
//!   samples outside the data) and `values`, one key per field holding `NV` rows of `NU`
//!   numbers (`values[field][j][i]`); `null` outside the data (JSON has no NaN).
//! - `.npy`: a little-endian `float32` array of shape `(NV, NU, nfields)` in C order,
//!   `a[j, i, f]`, fields in the order of [`PlaneSamples::fields`]; NaN outside the data.
//!   `float32` holds every value exactly: the reconstruction is reported as an `f32`.

use std::io::{self, Write};
use std::path::Path;

use super::plane::PlaneSamples;

/// The file formats of a sampled plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PlaneFormat {
    Csv,
    Json,
    Npy,
}

impl PlaneFormat {
    /// The format a file name's extension (`.csv`, `.json`, `.npy`, any case) stands for.
    pub fn of_path(path: &Path) -> Option<PlaneFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "csv" => Some(PlaneFormat::Csv),
            "json" => Some(PlaneFormat::Json),
            "npy" => Some(PlaneFormat::Npy),
            _ => None,
        }
    }

    /// The extension, `csv`, `json` or `npy`.
    pub fn name(self) -> &'static str {
        match self {
            PlaneFormat::Csv => "csv",
            PlaneFormat::Json => "json",
            PlaneFormat::Npy => "npy",
        }
    }
}

/// The sample-position rule, as the JSON output states it.
pub const SAMPLES_AT: &str =
    "cell centres: p(i, j) = origin + (i + 0.5) / NU * u + (j + 0.5) / NV * v";

/// Writes `s` to `out` in `format`.
pub fn write(out: &mut impl Write, s: &PlaneSamples, format: PlaneFormat) -> io::Result<()> {
    match format {
        PlaneFormat::Csv => write_csv(out, s),
        PlaneFormat::Json => write_json(out, s),
        PlaneFormat::Npy => write_npy(out, s),
    }
}

fn write_csv(out: &mut impl Write, s: &PlaneSamples) -> io::Result<()> {
    writeln!(out, "i,j,x,y,z,{}", s.fields.join(","))?;
    for j in 0..s.resolution.nv {
        for i in 0..s.resolution.nu {
            let p = s.point(i, j);
            write!(out, "{i},{j},{},{},{}", p[0], p[1], p[2])?;
            for v in s.sample(i, j) {
                write!(out, ",{}", f64::from(*v))?;
            }
            writeln!(out)?;
        }
    }
    Ok(())
}

fn write_json(out: &mut impl Write, s: &PlaneSamples) -> io::Result<()> {
    let head = serde_json::json!({
        "origin": s.plane.origin,
        "u": s.plane.u,
        "v": s.plane.v,
        "resolution": [s.resolution.nu, s.resolution.nv],
        "samples_at": SAMPLES_AT,
        "fields": s.fields,
        "outside": s.outside,
    });
    // The header's keys, then the values streamed field by field, row by row (a whole
    // `serde_json::Value` of them would take ten times their memory).
    let head = serde_json::to_string(&head)?;
    let head = head.strip_suffix('}').unwrap_or(&head);
    write!(out, "{head},\"values\":{{")?;
    let nu = s.resolution.nu as usize;
    let nf = s.fields.len();
    for (f, name) in s.fields.iter().enumerate() {
        if f > 0 {
            write!(out, ",")?;
        }
        serde_json::to_writer(&mut *out, name)?;
        write!(out, ":[")?;
        for (j, row) in s.values.chunks(nu * nf).enumerate() {
            write!(out, "{}[", if j > 0 { "," } else { "" })?;
            for (i, cell) in row.chunks(nf).enumerate() {
                if i > 0 {
                    write!(out, ",")?;
                }
                // NaN is written as `null`.
                serde_json::to_writer(&mut *out, &f64::from(cell[f]))?;
            }
            write!(out, "]")?;
        }
        write!(out, "]")?;
    }
    writeln!(out, "}}}}")
}

fn write_npy(out: &mut impl Write, s: &PlaneSamples) -> io::Result<()> {
    use npyz::WriterBuilder;
    let shape = [
        u64::from(s.resolution.nv),
        u64::from(s.resolution.nu),
        s.fields.len() as u64,
    ];
    let mut w = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&shape)
        .writer(out)
        .begin_nd()?;
    w.extend(s.values.iter().copied())?;
    w.finish()
}
