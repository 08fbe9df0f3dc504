//! `qbricks._qbricks`: the native half of the Python package `qbricks`.
//!
//! Argument conversion only: every entry point calls the libraries the CLIs call, the
//! same way (`qbricks-view render`, `probe`, `info`, `qbricks-bake`). The Python half
//! (`qbricks/__init__.py`) turns keyword arguments into the CLI's flags, which are parsed
//! here by the very `clap` definitions the CLI uses ([`Overrides`]), so a keyword means
//! exactly what its flag means. Errors become Python exceptions carrying the CLI's
//! one-line message; a panic becomes a `RuntimeError` (see [`guarded`]), never an abort.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{FromArgMatches, Parser, ValueEnum};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};

use preprocess::derive::Stencil;
use preprocess::inputs::Layout;
use preprocess::request::{bake_one, summary_json, BakeRequest};
use preprocess::sequence::{self, FrameDone};
use viewer::dataset::Dataset as Opened;
use viewer::mesh::Meshes;
use viewer::overlay;
use viewer::render::{Aov, AovTrace, AovValues, CancelToken, Renderer, Scene};
use viewer::view_state::{Overrides, ResolvedView, ViewState};

create_exception!(
    qbricks,
    FormatError,
    PyValueError,
    "A file that is not a valid .qbk brick file (truncated, corrupted, another format or \
     version): the message is the one `qbricks-view` prints."
);

/// Whether `cause` is a missing file, whichever library's error carries it.
fn is_not_found(cause: &(dyn std::error::Error + 'static)) -> bool {
    use files::input::InputErrorKind;
    let missing = |e: &std::io::Error| e.kind() == std::io::ErrorKind::NotFound;
    let missing_input = |k: &InputErrorKind| matches!(k, InputErrorKind::Io(e) if missing(e));
    if let Some(e) = cause.downcast_ref::<std::io::Error>() {
        return missing(e);
    }
    if let Some(e) = cause.downcast_ref::<files::input::InputError>() {
        return missing_input(&e.kind);
    }
    if let Some(e) = cause.downcast_ref::<preprocess::vdb::VdbError>() {
        // The VDB reader keeps the I/O error's text only.
        return matches!(e.kind, preprocess::vdb::ErrorKind::Io(_)) && !Path::new(&e.file).exists();
    }
    if let Some(viewer::view_state::ViewStateError::Io { error, .. }) = cause.downcast_ref() {
        return missing(error);
    }
    if let Some(e) = cause.downcast_ref::<viewer::mesh::MeshError>() {
        use viewer::mesh::MeshErrorKind;
        return match &e.kind {
            MeshErrorKind::Read(io) => missing(io),
            MeshErrorKind::Input(k) => missing_input(k),
            _ => false,
        };
    }
    if let Some(e) = format_error(cause) {
        return match &e.kind {
            format::FormatErrorKind::Io(io) => missing(io),
            format::FormatErrorKind::Input(k) => missing_input(k),
            _ => false,
        };
    }
    false
}

/// The `.qbk` format error `cause` is or carries.
fn format_error<'a>(
    cause: &'a (dyn std::error::Error + 'static),
) -> Option<&'a format::FormatError> {
    cause.downcast_ref::<format::FormatError>().or_else(|| {
        match cause.downcast_ref::<viewer::dataset::OpenError>() {
            Some(viewer::dataset::OpenError::Format(e)) => Some(e),
            _ => None,
        }
    })
}

/// The Python exception for an error of the libraries: `FileNotFoundError` when a file
/// is missing, `qbricks.FormatError` for a bad `.qbk` file, `KeyboardInterrupt` for a
/// bake stopped by Ctrl-C, `ValueError` otherwise; the message is the CLI's (`{err:#}`,
/// without the program's name).
fn to_py(err: anyhow::Error) -> PyErr {
    let msg = format!("{err:#}");
    for cause in err.chain() {
        if is_not_found(cause) {
            return PyFileNotFoundError::new_err(msg);
        }
        if cause.is::<preprocess::request::Cancelled>() {
            return PyKeyboardInterrupt::new_err(msg);
        }
        // A file that validates but whose tables the ray caster refuses.
        let refused = matches!(
            cause.downcast_ref(),
            Some(viewer::dataset::OpenError::Volume { .. })
        );
        if refused || format_error(cause).is_some() {
            return FormatError::new_err(msg);
        }
    }
    PyValueError::new_err(msg)
}

/// Runs `f`, turning its error into a Python exception and a panic into a `RuntimeError`
/// (a panic must not unwind across the FFI boundary).
fn guarded<T>(f: impl FnOnce() -> anyhow::Result<T>) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(to_py),
        Err(panic) => {
            let text = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_string());
            Err(PyRuntimeError::new_err(format!(
                "qbricks: internal error: {text}"
            )))
        }
    }
}

/// The view flags of `qbricks-view render`, parsed by the CLI's own definitions.
#[derive(Parser)]
#[command(name = "render", no_binary_name = true)]
struct RenderFlags {
    #[command(flatten)]
    view: Overrides,
}

fn parse_flags(flags: &[String]) -> anyhow::Result<Overrides> {
    let matches = <RenderFlags as clap::CommandFactory>::command()
        .try_get_matches_from(flags)
        .map_err(|e| anyhow::anyhow!("{}", first_line(&e.render().to_string())))?;
    Ok(RenderFlags::from_arg_matches(&matches)
        .map_err(|e| anyhow::anyhow!("{}", first_line(&e.render().to_string())))?
        .view)
}

/// clap's message without its usage lines.
fn first_line(text: &str) -> String {
    text.lines()
        .next()
        .unwrap_or_default()
        .trim_start_matches("error: ")
        .to_string()
}

/// A `.qbk` file opened and validated, memory-mapped for the object's life.
#[pyclass(module = "qbricks._qbricks", frozen)]
struct Dataset {
    inner: Arc<Opened>,
    path: PathBuf,
}

/// Where a render's view state comes from.
enum StateSource {
    Defaults,
    Json(String),
    File(PathBuf),
}

/// The effective view state, as `qbricks-view render` computes it
/// ([`Overrides::resolve`]): the state (a file, JSON text, or the data's defaults), then
/// the flags; with a renderer, `--colour-range visible` is applied too.
fn effective_state(
    ds: &Opened,
    path: &Path,
    source: &StateSource,
    view: &Overrides,
    renderer: Option<&Renderer>,
) -> anyhow::Result<(ViewState, Meshes)> {
    let vol = ds.volume();
    let given = match source {
        StateSource::Defaults => None,
        StateSource::Json(text) => Some(ViewState::from_json(Path::new("state"), text)?),
        StateSource::File(p) => Some(ViewState::load(p)?),
    };
    let ResolvedView {
        mut state,
        notes,
        warnings,
    } = view.resolve(vol, path, given)?;
    for w in warnings {
        eprintln!("qbricks: warning: {}: {w}", path.display());
    }
    for n in notes {
        eprintln!("qbricks: note: {n}");
    }
    let meshes = if state.meshes.is_empty() {
        Meshes::empty()
    } else {
        Meshes::load(&state.meshes)?
    };
    if let Some(renderer) = renderer {
        if let Some(note) = view
            .fit_visible_colours(renderer, vol, &mut state, &meshes)
            .with_context(|| path.display().to_string())?
        {
            eprintln!("qbricks: note: {note}");
        }
    }
    Ok((state, meshes))
}

fn state_source(state: Option<&Bound<'_, PyAny>>) -> PyResult<StateSource> {
    let Some(s) = state else {
        return Ok(StateSource::Defaults);
    };
    if s.is_none() {
        return Ok(StateSource::Defaults);
    }
    if let Ok(bytes) = s.downcast::<PyBytes>() {
        // JSON text (the Python half passes a dict so).
        let text = std::str::from_utf8(bytes.as_bytes())
            .map_err(|e| PyValueError::new_err(format!("state: not UTF-8 text: {e}")))?;
        return Ok(StateSource::Json(text.to_string()));
    }
    if let Ok(p) = s.extract::<PathBuf>() {
        return Ok(StateSource::File(p));
    }
    Err(PyValueError::new_err(
        "state: expected a view-state dict or the path of a view-state JSON file",
    ))
}

/// One rendered picture: RGBA bytes, and the depth when asked for.
struct Rendered {
    width: u32,
    height: u32,
    rgba: Vec<u8>,
    depth: Option<Vec<f32>>,
    /// The `aov` buffer as numbers (see [`viewer::render::AovTrace::values`]).
    aov: Option<AovValues>,
    state_json: String,
}

#[pymethods]
impl Dataset {
    /// The file's path.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// The fields in the file's order: a list of (name, min, max).
    #[getter]
    fn field_ranges(&self) -> Vec<(String, f32, f32)> {
        self.inner
            .volume()
            .fields
            .iter()
            .map(|f| (f.name.clone(), f.min, f.max))
            .collect()
    }

    /// `qbricks-view info --json` as JSON text.
    fn info_json(&self) -> PyResult<String> {
        guarded(|| {
            let info = viewer::info::info(self.inner.view());
            Ok(serde_json::to_string(&info)?)
        })
    }

    /// The stored histogram of `field`: (counts, min, max), equal bins over [min, max].
    fn histogram(&self, field: &str) -> PyResult<(Vec<u64>, f32, f32)> {
        guarded(|| {
            let vol = self.inner.volume();
            let i = vol
                .field_index(field)
                .with_context(|| self.path.display().to_string())?;
            let f = &self.inner.view().file().fields[i];
            let counts = f.histogram.iter().map(|c| c.to_native()).collect();
            Ok((counts, f.min.to_native(), f.max.to_native()))
        })
    }

    /// The effective view state of a render with these flags, as JSON text.
    #[pyo3(signature = (state, flags))]
    fn state_json(&self, state: Option<&Bound<'_, PyAny>>, flags: Vec<String>) -> PyResult<String> {
        let source = state_source(state)?;
        guarded(|| {
            let view = parse_flags(&flags)?;
            let (state, _) = effective_state(&self.inner, &self.path, &source, &view, None)?;
            Ok(state.to_json())
        })
    }

    /// Renders as `qbricks-view render` does: returns (rgba (H, W, 4) uint8, depth (H, W)
    /// float32 or None, the `aov` buffer (H, W, C) float32 or None, the effective state as
    /// JSON text). The GIL is released meanwhile; Ctrl-C stops the render.
    #[pyo3(signature = (state, flags, *, threads=None, aov=None, title=None, depth=false))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        state: Option<&Bound<'py, PyAny>>,
        flags: Vec<String>,
        threads: Option<usize>,
        aov: Option<String>,
        title: Option<String>,
        depth: bool,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let job = RenderJob {
            ds: Arc::clone(&self.inner),
            path: self.path.clone(),
            source: state_source(state)?,
            flags,
            threads,
            aov,
            title,
            depth,
        };
        let cancel = CancelToken::new();
        let out = run_interruptibly(py, || cancel.cancel(), || job.run(&cancel))?
            .ok_or_else(|| PyRuntimeError::new_err("qbricks: render cancelled"))?;
        let (w, h) = (out.width as usize, out.height as usize);
        let image = PyArray1::from_vec(py, out.rgba).reshape([h, w, 4])?;
        let depth = match out.depth {
            Some(d) => PyArray1::from_vec(py, d)
                .reshape([h, w])?
                .into_any()
                .unbind(),
            None => py.None(),
        };
        let aov = match out.aov {
            Some(a) => PyArray1::from_vec(py, a.values)
                .reshape([h, w, a.channels])?
                .into_any()
                .unbind(),
            None => py.None(),
        };
        PyTuple::new(
            py,
            [
                image.into_any().unbind(),
                depth,
                aov,
                out.state_json.into_pyobject(py)?.into_any().unbind(),
            ],
        )
    }

    /// Every field (or those of `fields`) sampled on a plane as `qbricks-view probe --plane
    /// SPEC --resolution RES` does: returns (values (NV, NU, F) float32, field names, origin,
    /// u, v, samples outside). The GIL is released meanwhile.
    #[pyo3(signature = (plane, resolution=None, fields=None))]
    #[allow(clippy::type_complexity)]
    fn probe_plane<'py>(
        &self,
        py: Python<'py>,
        plane: String,
        resolution: Option<String>,
        fields: Option<Vec<String>>,
    ) -> PyResult<(
        Bound<'py, PyAny>,
        Vec<String>,
        [f64; 3],
        [f64; 3],
        [f64; 3],
        u64,
    )> {
        use viewer::probe::plane::{self as pl, PlaneSpec, ResolutionSpec};
        let ds = Arc::clone(&self.inner);
        let path = self.path.clone();
        let samples = py.allow_threads(move || {
            guarded(|| {
                let spec = PlaneSpec::parse(&plane).map_err(|e| anyhow::anyhow!("plane: {e}"))?;
                let res = match &resolution {
                    Some(r) => {
                        ResolutionSpec::parse(r).map_err(|e| anyhow::anyhow!("resolution: {e}"))?
                    }
                    None => ResolutionSpec::default(),
                };
                let vol = ds.volume();
                if vol.fields.is_empty() {
                    anyhow::bail!("{}: the file has no fields", path.display());
                }
                let fields: Vec<usize> = match &fields {
                    None => (0..vol.fields.len()).collect(),
                    Some(names) => {
                        let mut out = Vec::new();
                        for name in names {
                            let f = vol
                                .field_index(name.trim())
                                .map_err(|e| e.named_by("fields"))?;
                            if out.contains(&f) {
                                anyhow::bail!("fields: {:?} is named twice", name.trim());
                            }
                            out.push(f);
                        }
                        out
                    }
                };
                let b = &ds.view().file().bounds;
                let plane = spec
                    .resolve(b.min.map(|x| x.to_native()), b.max.map(|x| x.to_native()))
                    .map_err(|e| anyhow::anyhow!("plane: {e}"))?;
                let res = res.resolve(&plane)?;
                pl::check_memory(res, fields.len())?;
                let samples = pl::sample(vol, &plane, res, &fields)?;
                vol.check_structure(&path)?;
                Ok(samples)
            })
        })?;
        let (nu, nv, nf) = (
            samples.resolution.nu as usize,
            samples.resolution.nv as usize,
            samples.fields.len(),
        );
        let values = PyArray1::from_vec(py, samples.values)
            .reshape([nv, nu, nf])?
            .into_any();
        Ok((
            values,
            samples.fields,
            samples.plane.origin,
            samples.plane.u,
            samples.plane.v,
            samples.outside,
        ))
    }

    /// Every field at `points` ((N, 3) float64, world coordinates; NaN outside the data),
    /// the gradient of `field` (default: `q`, else the first) and the shading normal, as
    /// `qbricks-view probe` reports them.
    #[pyo3(signature = (points, field=None))]
    fn probe<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
        field: Option<String>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if points.shape().len() != 2 || points.shape()[1] != 3 {
            return Err(PyValueError::new_err(format!(
                "points: expected an (N, 3) array, found shape {:?}",
                points.shape()
            )));
        }
        let pts: Vec<[f64; 3]> = points
            .as_array()
            .rows()
            .into_iter()
            .map(|r| [r[0], r[1], r[2]])
            .collect();
        let ds = Arc::clone(&self.inner);
        let path = self.path.clone();
        let (names, probed) = py.allow_threads(move || {
            guarded(|| {
                let vol = ds.volume();
                if vol.fields.is_empty() {
                    anyhow::bail!("{}: the file has no fields", path.display());
                }
                let gf = match &field {
                    Some(name) => vol
                        .field_index(name)
                        .with_context(|| path.display().to_string())?,
                    None => viewer::probe::default_field(vol),
                };
                let names: Vec<String> = vol.fields.iter().map(|f| f.name.clone()).collect();
                let probed = viewer::probe::probe(vol, &pts, gf);
                vol.check_structure(&path)?;
                Ok((names, probed))
            })
        })?;
        let n = probed.len();
        let out = PyDict::new(py);
        for (i, name) in names.iter().enumerate() {
            let v: Vec<f64> = probed.iter().map(|p| p.values[i]).collect();
            out.set_item(name, PyArray1::from_vec(py, v))?;
        }
        let flat = |f: &dyn Fn(&viewer::probe::Probe) -> [f64; 3]| -> Vec<f64> {
            probed.iter().flat_map(f).collect()
        };
        out.set_item(
            "gradient",
            PyArray1::from_vec(py, flat(&|p| p.gradient)).reshape([n, 3])?,
        )?;
        out.set_item(
            "normal",
            PyArray1::from_vec(py, flat(&|p| p.normal)).reshape([n, 3])?,
        )?;
        Ok(out)
    }
}

/// What one `Dataset.render` call asks for.
struct RenderJob {
    ds: Arc<Opened>,
    path: PathBuf,
    source: StateSource,
    flags: Vec<String>,
    threads: Option<usize>,
    aov: Option<String>,
    title: Option<String>,
    depth: bool,
}

impl RenderJob {
    /// Renders as `qbricks-view render` does; `None` when `cancel` stopped it.
    fn run(self, cancel: &CancelToken) -> anyhow::Result<Option<Rendered>> {
        let RenderJob {
            ds,
            path,
            source,
            flags,
            threads,
            aov,
            title,
            depth,
        } = self;

        files::limits::threads(threads)?;
        let aov = match aov {
            None => None,
            Some(a) => Some(
                Aov::from_str(&a, true)
                    .map_err(|_| anyhow::anyhow!("aov: unknown buffer {a:?}"))?,
            ),
        };
        let view = parse_flags(&flags)?;
        let renderer = Renderer::new(threads).context("starting worker threads")?;
        let (state, meshes) = effective_state(&ds, &path, &source, &view, Some(&renderer))?;
        let vol = ds.volume();
        let scene = Scene::new(vol, &state, &meshes).with_context(|| path.display().to_string())?;
        let (frame, aov) = match aov {
            Some(aov) => {
                let trace = renderer.install(|| AovTrace::new(&scene));
                (trace.picture(&scene, aov), Some(trace.values(aov)))
            }
            None => match renderer.render_cancellable(&scene, cancel) {
                Some(f) => (f, None),
                None => return Ok(None),
            },
        };
        vol.check_structure(&path)?;
        let title = title.unwrap_or_else(|| overlay::file_title(&path));
        let rgb8 = overlay::figure(&frame, &state, vol, aov.is_some(), &title);
        let mut rgba = Vec::with_capacity(rgb8.len() / 3 * 4);
        for p in rgb8.chunks_exact(3) {
            rgba.extend_from_slice(&[p[0], p[1], p[2], 255]);
        }
        Ok(Some(Rendered {
            width: frame.width,
            height: frame.height,
            rgba,
            depth: depth.then_some(frame.depth),
            aov,
            state_json: state.to_json(),
        }))
    }
}

/// Runs `job` on a thread of its own with the GIL released, while this thread checks for
/// signals (Ctrl-C) every 20 ms: a Python exception from a signal handler calls `stop`
/// (which asks the job to end early) and is raised once the job has ended. A panic in the
/// job is a `RuntimeError`.
fn run_interruptibly<T: Send>(
    py: Python<'_>,
    stop: impl Fn(),
    job: impl FnOnce() -> anyhow::Result<T> + Send,
) -> PyResult<T> {
    let done = AtomicBool::new(false);
    let mut interrupted: Option<PyErr> = None;
    let result = std::thread::scope(|s| {
        let handle = s.spawn(|| {
            let r = guarded(job);
            done.store(true, Ordering::Release);
            r
        });
        while !done.load(Ordering::Acquire) {
            py.allow_threads(|| {
                let t = Instant::now();
                while !done.load(Ordering::Acquire) && t.elapsed() < Duration::from_millis(20) {
                    std::thread::sleep(Duration::from_millis(1));
                }
            });
            if interrupted.is_none() {
                if let Err(e) = py.check_signals() {
                    stop();
                    interrupted = Some(e);
                }
            }
        }
        handle.join()
    });
    match (result, interrupted) {
        (_, Some(e)) => Err(e),
        (Ok(r), None) => r,
        (Err(_), None) => Err(PyRuntimeError::new_err(
            "qbricks: internal error: worker thread",
        )),
    }
}
/// Opens and validates a `.qbk` file (the payload checksum too unless `checksum` is false).
#[pyfunction]
#[pyo3(signature = (path, *, checksum=true))]
fn open(py: Python<'_>, path: PathBuf, checksum: bool) -> PyResult<Dataset> {
    let p = path.clone();
    let inner = py.allow_threads(move || {
        guarded(|| {
            let options = viewer::dataset::render_options(checksum);
            Ok(Opened::open_with(&p, &options)?)
        })
    })?;
    Ok(Dataset {
        inner: Arc::new(inner),
        path,
    })
}

/// Bakes an OpenVDB file into a `.qbk` file as `qbricks-bake SRC -o OUT --json` does, or
/// every frame of a sequence when `src` is a frame pattern (`in_####.vdb`, and `out` one
/// too); returns the JSON summary as text. The GIL is released meanwhile; Ctrl-C stops
/// the bake between stages (or frames) and raises `KeyboardInterrupt`.
#[pyfunction]
#[pyo3(signature = (src, out, *, fields=None, grids=Vec::new(), velocity=Vec::new(),
    layout="auto".to_string(), stencil="central".to_string(), max_brick=None, strict=false,
    threads=None, jobs=None, progress=false, memory=None))]
#[allow(clippy::too_many_arguments)]
fn bake(
    py: Python<'_>,
    src: PathBuf,
    out: Option<PathBuf>,
    fields: Option<Vec<String>>,
    grids: Vec<String>,
    velocity: Vec<String>,
    layout: String,
    stencil: String,
    max_brick: Option<u32>,
    strict: bool,
    threads: Option<usize>,
    jobs: Option<usize>,
    progress: bool,
    memory: Option<String>,
) -> PyResult<String> {
    let cancel = AtomicBool::new(false);
    run_interruptibly(
        py,
        || cancel.store(true, Ordering::Relaxed),
        || {
            let start = Instant::now();
            files::limits::threads(threads)?;
            let request = BakeRequest {
                fields,
                grids,
                velocity,
                layout: Layout::from_str(&layout, true).map_err(|_| {
                    anyhow::anyhow!("layout: expected auto, centred or staggered, found {layout:?}")
                })?,
                stencil: Stencil::from_str(&stencil.replace('_', "-"), true).map_err(|_| {
                    anyhow::anyhow!("stencil: expected central or cross-level, found {stencil:?}")
                })?,
                max_brick: max_brick.unwrap_or(preprocess::bake::DEFAULT_MAX_BRICK),
                strict,
                threads,
                memory: memory
                    .map(|m| files::limits::memory_size("memory", &m))
                    .transpose()?,
            };
            let plan = request.plan()?;
            let seconds = || start.elapsed().as_secs_f64();
            if let Some(pattern) = sequence::input_pattern(&src)? {
                let on_frame = |f: FrameDone| {
                    if let Err(e) = f.result {
                        eprintln!("qbricks-bake: frame {}: {e:#}", f.frame);
                    }
                    if progress {
                        eprintln!(
                            "qbricks-bake: {:7.2} s  frame {} done ({}/{})",
                            seconds(),
                            f.frame,
                            f.done,
                            f.total
                        );
                    }
                };
                let report = sequence::bake_sequence(
                    &src,
                    &pattern,
                    out.as_deref(),
                    &plan,
                    jobs,
                    &cancel,
                    &on_frame,
                )?;
                if let Some(message) = report.failure() {
                    anyhow::bail!(message);
                }
                return Ok(report.summary(seconds()).to_string());
            }
            let stage = |name: &str| {
                if progress {
                    eprintln!("qbricks-bake: {:7.2} s  {name}", seconds());
                }
            };
            let (output, summary) = bake_one(&src, out.as_deref(), "out", &plan, &stage, &cancel)?;
            for w in &summary.warnings {
                eprintln!("qbricks-bake: warning: {}: {w}", src.display());
            }
            let mut v = summary_json(&summary, seconds(), &output)?;
            v["warnings"] = serde_json::json!(summary.warnings);
            Ok(v.to_string())
        },
    )
}

/// The PNG of an (H, W, 3 or 4) uint8 picture (alpha dropped), encoded as `qbricks-view
/// render` encodes its pictures.
fn png_of(image: &PyReadonlyArray3<'_, u8>) -> anyhow::Result<Vec<u8>> {
    let shape = image.shape();
    if shape.len() != 3 || !(shape[2] == 3 || shape[2] == 4) {
        anyhow::bail!(
            "image: expected an (H, W, 3) or (H, W, 4) uint8 array, found shape {shape:?}"
        );
    }
    let (h, w) = (shape[0], shape[1]);
    let (w32, h32) = (u32::try_from(w)?, u32::try_from(h)?);
    viewer::film::check_frame_memory(w32, h32, 1)?;
    let a = image.as_array();
    let mut rgb = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            rgb.extend_from_slice(&[a[[y, x, 0]], a[[y, x, 1]], a[[y, x, 2]]]);
        }
    }
    Ok(viewer::film::encode_png_rgb8(w32, h32, rgb)?)
}

/// The PNG bytes of an (H, W, 3 or 4) uint8 picture.
#[pyfunction]
fn png_bytes<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<'py, u8>,
) -> PyResult<Bound<'py, PyBytes>> {
    let png = guarded(|| png_of(&image))?;
    Ok(PyBytes::new(py, &png))
}

/// Refuses to write `path` over one of `inputs` (the files a picture or state was made
/// from), as the CLI refuses (`files::guard`).
fn check_output(role: &str, path: &Path, inputs: &[PathBuf]) -> anyhow::Result<()> {
    let mut guard = files::guard::Guard::new();
    for i in inputs {
        guard.input("an input of this picture", i);
    }
    guard.output(role, path).check()?;
    Ok(())
}

/// Writes an (H, W, 3 or 4) uint8 picture as a PNG file, atomically (a temporary file
/// renamed over `path`), as the CLI writes its pictures; never over one of `inputs` (the
/// brick file, the state file and meshes it was rendered from).
#[pyfunction]
#[pyo3(signature = (image, path, inputs=Vec::new()))]
fn save_png(image: PyReadonlyArray3<'_, u8>, path: PathBuf, inputs: Vec<PathBuf>) -> PyResult<()> {
    guarded(|| {
        check_output("save", &path, &inputs)?;
        let png = png_of(&image)?;
        files::output::write_atomic(&path, |f| std::io::Write::write_all(f, &png))
            .with_context(|| path.display().to_string())?;
        Ok(())
    })
}

/// A view-state file read and checked as `--state` reads it, as JSON text.
#[pyfunction]
fn load_state(path: PathBuf) -> PyResult<String> {
    guarded(|| Ok(ViewState::load(&path)?.to_json()))
}

/// Writes view-state JSON text to `path` as `--save-state` does (validated, atomically),
/// never over one of its meshes or `inputs`.
#[pyfunction]
#[pyo3(signature = (text, path, inputs=Vec::new()))]
fn save_state(text: &str, path: PathBuf, inputs: Vec<PathBuf>) -> PyResult<()> {
    guarded(|| {
        let state = ViewState::from_json(Path::new("state"), text)?;
        let mut inputs = inputs;
        inputs.extend(state.meshes.iter().map(|m| m.path.clone()));
        check_output("save", &path, &inputs)?;
        Ok(state.save(&path)?)
    })
}

/// A view state given as JSON text, read and validated as a state file is, written back
/// as `--save-state` writes it: what `qbricks.ViewState` holds.
#[pyfunction]
fn normalize_state(text: &str) -> PyResult<String> {
    guarded(|| Ok(ViewState::from_json(Path::new("state"), text)?.to_json()))
}

#[pymodule]
fn _qbricks(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Dataset>()?;
    m.add_function(wrap_pyfunction!(open, m)?)?;
    m.add_function(wrap_pyfunction!(bake, m)?)?;
    m.add_function(wrap_pyfunction!(normalize_state, m)?)?;
    m.add_function(wrap_pyfunction!(save_state, m)?)?;
    m.add_function(wrap_pyfunction!(load_state, m)?)?;
    m.add_function(wrap_pyfunction!(png_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(save_png, m)?)?;
    m.add("FormatError", m.py().get_type::<FormatError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
