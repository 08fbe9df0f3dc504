//! `qbricks-view probe`.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context};
use files::guard::Guard;
use files::input::{read_whole, Limits};
use files::output::QuietStdout;
use qbricks_viewer::probe;
use qbricks_viewer::probe::plane::{self, PlaneSamples, PlaneSpec, ResolutionSpec};
use qbricks_viewer::probe::plane_file::{self, PlaneFormat};
use qbricks_viewer::volume::Volume;

#[derive(clap::Args)]
pub struct Args {
    /// Brick file to probe.
    pub file: PathBuf,
    /// CSV file of points, one `x,y,z` per line (optional header line).
    #[arg(long, conflicts_with_all = ["line", "plane"])]
    pub points: Option<PathBuf>,
    /// Evenly spaced points on a segment: x0,y0,z0:x1,y1,z1:N.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "plane")]
    pub line: Option<String>,
    /// Every field on a plane, sampled on a grid: OX,OY,OZ:UX,UY,UZ:VX,VY,VZ (an origin
    /// corner and two edge vectors, whose lengths are the patch's extent), or x=C, y=C, z=C
    /// (the data's extent in the other two axes). Sample (i, j) lies at
    /// O + (i+0.5)/NU·U + (j+0.5)/NV·V.
    #[arg(long, allow_hyphen_values = true)]
    pub plane: Option<String>,
    /// With --plane: samples along U and V, NU,NV; or N along the longer edge and the other
    /// in proportion [default: 256]. Each side 1..=16384.
    #[arg(long, requires = "plane")]
    pub resolution: Option<String>,
    /// With --plane: the fields to sample, in this order (the order of the columns, of the
    /// JSON keys and of the .npy's last axis) [default: every field, in the file's order].
    #[arg(long, requires = "plane", value_delimiter = ',')]
    pub fields: Option<Vec<String>>,
    /// With --plane: the output file, written atomically; its extension (.csv, .json,
    /// .npy) chooses the format [default: CSV on stdout].
    #[arg(short = 'o', long = "output", requires = "plane")]
    pub output: Option<PathBuf>,
    /// With --plane: the output's format, whatever -o is called [default: from -o's
    /// extension, else CSV].
    #[arg(long, value_enum, requires = "plane", conflicts_with = "json")]
    pub format: Option<PlaneFormat>,
    /// Field whose gradient is reported [default: q, else the first field].
    #[arg(long, conflicts_with = "plane")]
    pub field: Option<String>,
    /// Print a JSON list (one object per point) instead of CSV; with --plane, the same as
    /// --format json.
    #[arg(long)]
    pub json: bool,
}

/// Largest points CSV read (regular file, device or pipe): 1 GiB of text is about 30 M
/// points, far more than a probe is for.
const MAX_CSV_BYTES: u64 = 1 << 30;

pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(spec) = &args.plane {
        return run_plane(&args, spec);
    }
    // clap lets a flag that `requires` --plane through when --plane's absence is excused by
    // a flag it conflicts with (--points, --line), so say it here.
    let plane_only = [
        ("--resolution", args.resolution.is_some()),
        ("--fields", args.fields.is_some()),
        ("-o", args.output.is_some()),
        ("--format", args.format.is_some()),
    ];
    if let Some((flag, _)) = plane_only.iter().find(|(_, given)| *given) {
        bail!("{flag} is for --plane; --points and --line print their report on stdout");
    }
    let points = match (&args.points, &args.line) {
        (Some(p), None) => {
            let bytes = read_whole(p, Limits::both(MAX_CSV_BYTES))?;
            let text = std::str::from_utf8(&bytes)
                .map_err(|e| anyhow::anyhow!("{}: not UTF-8 text: {e}", p.display()))?;
            probe::parse_points_csv(text).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?
        }
        (None, Some(l)) => probe::parse_line(l).map_err(|e| anyhow::anyhow!("--line: {e}"))?,
        _ => bail!(
            "expected exactly one of --points CSV, --line x0,y0,z0:x1,y1,z1:N or --plane \
             OX,OY,OZ:UX,UY,UZ:VX,VY,VZ"
        ),
    };
    let view = format::BrickFileView::open(&args.file)?;
    let vol = Volume::new(&view).with_context(|| format!("{}", args.file.display()))?;
    if vol.fields.is_empty() {
        bail!("{}: the file has no fields", args.file.display());
    }
    let gf = match &args.field {
        Some(name) => vol
            .field_index(name)
            .with_context(|| format!("{}", args.file.display()))?,
        None => probe::default_field(&vol),
    };
    let mut out = std::io::BufWriter::new(QuietStdout::new());
    let format = if args.json {
        probe::ReportFormat::Json
    } else {
        probe::ReportFormat::Csv
    };
    probe::write_report(&mut out, &vol, &points, gf, format)?;
    out.flush()?;
    Ok(())
}

/// `--plane`: checks every argument and the outputs against the inputs, samples, then
/// writes the output (through `files::output`: complete or absent) and one summary line on
/// stderr.
fn run_plane(args: &Args, spec: &str) -> anyhow::Result<()> {
    let spec = PlaneSpec::parse(spec).map_err(|e| anyhow!("--plane: {e}"))?;
    let resolution = match &args.resolution {
        Some(r) => ResolutionSpec::parse(r).map_err(|e| anyhow!("--resolution: {e}"))?,
        None => ResolutionSpec::default(),
    };
    if let Some(out) = &args.output {
        Guard::new()
            .input("brick file", &args.file)
            .output("-o", out)
            .check()?;
    }
    let format = plane_format(args)?;
    if args.output.is_none() && format == PlaneFormat::Npy {
        bail!("--format npy: the array is binary; give -o FILE.npy (or -o /dev/stdout)");
    }
    let view = format::BrickFileView::open(&args.file)?;
    let vol = Volume::new(&view).with_context(|| format!("{}", args.file.display()))?;
    if vol.fields.is_empty() {
        bail!("{}: the file has no fields", args.file.display());
    }
    let fields = plane_fields(&vol, args.fields.as_deref())
        .with_context(|| format!("{}", args.file.display()))?;
    let b = &view.file().bounds;
    let plane = spec
        .resolve(b.min.map(|x| x.to_native()), b.max.map(|x| x.to_native()))
        .map_err(|e| anyhow!("--plane: {e}"))?;
    let res = resolution.resolve(&plane)?;
    plane::check_memory(res, fields.len())?;
    let samples = plane::sample(&vol, &plane, res, &fields)?;
    let to = match &args.output {
        Some(out) => {
            files::output::write_atomic(out, |f| -> std::io::Result<()> {
                let mut w = std::io::BufWriter::new(f);
                plane_file::write(&mut w, &samples, format)?;
                w.flush()
            })
            .map_err(|e| anyhow!("{}: {e}", out.display()))?;
            out.display().to_string()
        }
        None => {
            let mut out = std::io::BufWriter::new(QuietStdout::new());
            plane_file::write(&mut out, &samples, format)?;
            out.flush()?;
            "stdout".to_string()
        }
    };
    eprintln!("qbricks-view: {}", summary(&samples, format, &to));
    if samples.outside == res.count() {
        eprintln!("qbricks-view: warning: --plane: every sample lies outside the data");
    }
    Ok(())
}

/// The output's format: `--format` (or `--json`), else `-o`'s extension, else CSV; a
/// format and an extension that disagree, or an extension that names none, are refused.
fn plane_format(args: &Args) -> anyhow::Result<PlaneFormat> {
    let given = args.format.or(args.json.then_some(PlaneFormat::Json));
    let Some(out) = &args.output else {
        return Ok(given.unwrap_or(PlaneFormat::Csv));
    };
    match (given, PlaneFormat::of_path(out), out.extension()) {
        (Some(f), Some(e), _) if f != e => bail!(
            "-o {}: the name says {} but --format{} says {}",
            out.display(),
            e.name(),
            if args.json { " (--json)" } else { "" },
            f.name()
        ),
        (Some(f), _, _) | (None, Some(f), _) => Ok(f),
        (None, None, Some(ext)) => bail!(
            "-o {}: no format is named .{}: name the file .csv, .json or .npy, or give --format",
            out.display(),
            ext.to_string_lossy()
        ),
        (None, None, None) => Ok(PlaneFormat::Csv),
    }
}

/// `--fields` as indices (every field by default); unknown or repeated names are refused.
fn plane_fields(vol: &Volume, names: Option<&[String]>) -> anyhow::Result<Vec<usize>> {
    let Some(names) = names else {
        return Ok((0..vol.fields.len()).collect());
    };
    let mut fields = Vec::new();
    for name in names {
        let f = vol
            .field_index(name.trim())
            .map_err(|e| e.named_by("--fields"))?;
        if fields.contains(&f) {
            bail!("--fields: {:?} is named twice", name.trim());
        }
        fields.push(f);
    }
    Ok(fields)
}

/// One line: what was sampled, where it went, the layout of a `.npy`, and how many samples
/// lie outside the data.
fn summary(s: &PlaneSamples, format: PlaneFormat, to: &str) -> String {
    let (nu, nv, nf) = (s.resolution.nu, s.resolution.nv, s.fields.len());
    let names = s.fields.join(", ");
    let layout = match format {
        PlaneFormat::Npy => format!(
            " as float32 [j, i, field], shape ({nv}, {nu}, {nf}), fields in that order: {names}"
        ),
        _ => String::new(),
    };
    format!(
        "--plane: {nu}x{nv} samples (NU x NV) of {names} on origin {:?} u {:?} v {:?}, \
         written to {to}{layout}; {} outside the data (NaN)",
        s.plane.origin, s.plane.u, s.plane.v, s.outside
    )
}
