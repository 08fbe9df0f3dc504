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
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyTuple};

use preprocess::bake::{bake_with_progress, BakeOptions, BakeSummary};
use preprocess::derive::Stencil;
use preprocess::fields::FieldKind;
use preprocess::inputs::{read_inputs, Layout, ReadError, ReadOptions};
use preprocess::vdb::VdbFile;
use viewer::dataset::Dataset as Opened;
use viewer::mesh::Meshes;
use viewer::overlay;
use viewer::render::{Aov, CancelToken, Renderer, Scene};
use viewer::view_state::{Overrides, ViewState};

create_exception!(
    qbricks,
    FormatError,
    PyValueError,
    "A file that is not a valid .qbk brick file (truncated, corrupted, another format or \
     version): the message is the one `qbricks-view` prints."
);

/// The Python exception for an error of the libraries: `FileNotFoundError` when a file
/// is missing, `qbricks.FormatError` for a bad `.qbk` file, `ValueError` otherwise; the
/// message is the CLI's (`{err:#}`, without the program's name).
fn to_py(err: anyhow::Error) -> PyErr {
    let msg = format!("{err:#}");
    for cause in err.chain() {
        // The VDB reader keeps the I/O error's text only.
        if let Some(e) = cause.downcast_ref::<preprocess::vdb::VdbError>() {
            if matches!(e.kind, preprocess::vdb::ErrorKind::Io(_)) && !Path::new(&e.file).exists() {
                return PyFileNotFoundError::new_err(msg);
            }
        }
        if let Some(viewer::view_state::ViewStateError::Io { error, .. }) = cause.downcast_ref() {
            if error.kind() == std::io::ErrorKind::NotFound {
                return PyFileNotFoundError::new_err(msg);
            }
        }
        if let Some(e) = cause.downcast_ref::<files::input::InputError>() {
            if let files::input::InputErrorKind::Io(io) = &e.kind {
                if io.kind() == std::io::ErrorKind::NotFound {
                    return PyFileNotFoundError::new_err(msg);
                }
            }
        }
        // A file that validates but whose tables the ray caster refuses.
        if let Some(viewer::dataset::OpenError::Volume { .. }) = cause.downcast_ref() {
            return FormatError::new_err(msg);
        }
        if let Some(e) = cause.downcast_ref::<std::io::Error>() {
            if e.kind() == std::io::ErrorKind::NotFound {
                return PyFileNotFoundError::new_err(msg);
            }
        }
        let format_error =
            cause
                .downcast_ref::<format::FormatError>()
                .or_else(
                    || match cause.downcast_ref::<viewer::dataset::OpenError>() {
                        Some(viewer::dataset::OpenError::Format(e)) => Some(e),
                        _ => None,
                    },
                );
        if let Some(e) = format_error {
            let missing = match &e.kind {
                format::FormatErrorKind::Io(io) => io.kind() == std::io::ErrorKind::NotFound,
                format::FormatErrorKind::Input(files::input::InputErrorKind::Io(io)) => {
                    io.kind() == std::io::ErrorKind::NotFound
                }
                _ => false,
            };
            return if missing {
                PyFileNotFoundError::new_err(msg)
            } else {
                FormatError::new_err(msg)
            };
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

/// The effective view state, as `qbricks-view render` computes it: the state (a file, JSON
/// text, or the data's defaults), then the flags, then framing and validation.
fn effective_state(
    ds: &Opened,
    path: &Path,
    source: &StateSource,
    view: &Overrides,
    renderer: Option<&Renderer>,
) -> anyhow::Result<(ViewState, Meshes)> {
    let vol = ds.volume();
    let (mut state, given) = match source {
        StateSource::Defaults => (ViewState::default_for_volume(vol), false),
        StateSource::Json(text) => (ViewState::from_json(Path::new("state"), text)?, true),
        StateSource::File(p) => (ViewState::load(p)?, true),
    };
    let notes = view
        .apply(&mut state, given)
        .map_err(|m| anyhow::anyhow!(m))?;
    view.apply_fields(&mut state, &vol.fields)
        .with_context(|| path.display().to_string())?;
    if !given && !view.places_camera() {
        state.frame_surface(vol);
    }
    state
        .validate()
        .map_err(|m| anyhow::anyhow!("view state: {m}"))?;
    if let Some(w) = state.iso_outside_range(&vol.fields) {
        eprintln!("qbricks: warning: {}: {w}", path.display());
    }
    viewer::film::check_frame_memory(state.width, state.height, 1)?;
    for n in notes {
        eprintln!("qbricks: note: {n}");
    }
    let meshes = if state.meshes.is_empty() {
        Meshes::empty()
    } else {
        Meshes::load(&state.meshes)?
    };
    if let Some(renderer) = renderer {
        if view.wants_visible_range() {
            let range = renderer
                .fit_colours_to_visible(vol, &mut state, &meshes, |r| view.colour_scale(r))
                .with_context(|| path.display().to_string())?;
            if range.is_none() {
                eprintln!(
                    "qbricks: note: colour_range='visible': no surface in the picture; the \
                     colour map keeps the field's range"
                );
            }
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
    /// float32 or None, the effective state as JSON text). The GIL is released meanwhile.
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
        let out = run_interruptibly(py, move |cancel| job.run(cancel))?;
        let (w, h) = (out.width as usize, out.height as usize);
        let image = PyArray1::from_vec(py, out.rgba).reshape([h, w, 4])?;
        let depth = match out.depth {
            Some(d) => PyArray1::from_vec(py, d)
                .reshape([h, w])?
                .into_any()
                .unbind(),
            None => py.None(),
        };
        PyTuple::new(
            py,
            [
                image.into_any().unbind(),
                depth,
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
                Ok(pl::sample(vol, &plane, res, &fields)?)
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
                Ok((names, viewer::probe::probe(vol, &pts, gf)))
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
        let frame = match aov {
            Some(aov) => renderer.install(|| viewer::render::render_aov(&scene, aov)),
            None => match renderer.render_cancellable(&scene, cancel) {
                Some(f) => f,
                None => return Ok(None),
            },
        };
        let title = title.unwrap_or_else(|| {
            path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            )
        });
        let rgb8 = if aov.is_some() {
            viewer::film::to_rgb8(&frame.rgb)
        } else {
            overlay::picture(
                &frame,
                &state,
                Some(overlay::data_bounds(vol)),
                Some(&title),
            )
        };
        let mut rgba = Vec::with_capacity(rgb8.len() / 3 * 4);
        for p in rgb8.chunks_exact(3) {
            rgba.extend_from_slice(&[p[0], p[1], p[2], 255]);
        }
        Ok(Some(Rendered {
            width: frame.width,
            height: frame.height,
            rgba,
            depth: depth.then_some(frame.depth),
            state_json: state.to_json(),
        }))
    }
}

/// Runs `job` on a thread of its own with the GIL released, while this thread checks for
/// signals (Ctrl-C) every 20 ms: a Python exception from a signal handler cancels the job
/// and is raised once the job has stopped. A panic in the job is a `RuntimeError`.
fn run_interruptibly<T: Send>(
    py: Python<'_>,
    job: impl FnOnce(&CancelToken) -> anyhow::Result<Option<T>> + Send,
) -> PyResult<T> {
    let cancel = CancelToken::new();
    let done = AtomicBool::new(false);
    let mut interrupted: Option<PyErr> = None;
    let result = std::thread::scope(|s| {
        let handle = s.spawn(|| {
            let r = guarded(|| job(&cancel));
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
                    cancel.cancel();
                    interrupted = Some(e);
                }
            }
        }
        handle.join()
    });
    match (result, interrupted) {
        (_, Some(e)) => Err(e),
        (Ok(Ok(Some(v))), None) => Ok(v),
        (Ok(Ok(None)), None) => Err(PyRuntimeError::new_err("qbricks: render cancelled")),
        (Ok(Err(e)), None) => Err(e),
        (Err(_), None) => Err(PyRuntimeError::new_err(
            "qbricks: internal error: render thread",
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
            let options = format::OpenOptions {
                verify_checksum: checksum,
            };
            Ok(Opened::open_with(&p, &options)?)
        })
    })?;
    Ok(Dataset {
        inner: Arc::new(inner),
        path,
    })
}

/// Bakes an OpenVDB file into a `.qbk` file as `qbricks-bake SRC -o OUT --json` does;
/// returns its JSON summary as text. The GIL is released meanwhile.
#[pyfunction]
#[pyo3(signature = (src, out, *, fields=None, grids=Vec::new(), velocity=Vec::new(),
    layout="auto".to_string(), stencil="central".to_string(), max_brick=None, strict=false,
    threads=None, progress=false))]
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
    progress: bool,
) -> PyResult<String> {
    py.allow_threads(move || {
        guarded(|| {
            let start = Instant::now();
            files::limits::threads(threads)?;
            let output = out.clone().unwrap_or_else(|| src.with_extension("qbk"));
            let fields = match fields {
                None => None,
                Some(list) => Some(
                    list.iter()
                        .map(|s| {
                            FieldKind::parse_or_grid(s)
                                .ok_or_else(|| anyhow::anyhow!("fields: empty field name"))
                        })
                        .collect::<anyhow::Result<Vec<_>>>()?,
                ),
            };
            let extra: Vec<String> = fields
                .iter()
                .flatten()
                .filter_map(|k| match k {
                    FieldKind::Scalar(n) => Some(n.clone()),
                    _ => None,
                })
                .collect();
            let layout = match layout.as_str() {
                "auto" => Layout::Auto,
                "centred" | "centered" => Layout::Centred,
                "staggered" => Layout::Staggered,
                l => anyhow::bail!("layout: expected auto, centred or staggered, found {l:?}"),
            };
            let stencil = match stencil.as_str() {
                "central" => Stencil::Central,
                "cross-level" | "cross_level" => Stencil::CrossLevel,
                s => anyhow::bail!("stencil: expected central or cross-level, found {s:?}"),
            };
            let read = ReadOptions {
                grids: grids.clone(),
                velocity,
                layout,
                extra,
            };
            let mut opts = BakeOptions {
                grids,
                fields,
                stencil,
                max_brick: max_brick.unwrap_or(preprocess::bake::DEFAULT_MAX_BRICK),
                strict,
                threads,
                ..BakeOptions::default()
            };
            files::guard::Guard::new()
                .input("input file", &src)
                .output(
                    if out.is_some() {
                        "out"
                    } else {
                        "the default output (the input with .qbk)"
                    },
                    &output,
                )
                .check()?;
            let input_name = src.display().to_string();
            let stage = |name: &str| {
                if progress {
                    let t = start.elapsed().as_secs_f64();
                    eprintln!("qbricks-bake: {t:7.2} s  {name}");
                }
            };
            opts.source = src
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            stage("reading VDB");
            let file = VdbFile::open(&src)?;
            let (grids, staggered) = match read_inputs(&file, &read) {
                Ok(v) => v,
                Err(ReadError::Vdb(e)) => return Err(e.into()),
                Err(e) => return Err(anyhow::Error::new(e).context(input_name)),
            };
            opts.staggered = staggered;
            drop(file);
            let (brick_file, summary) =
                bake_with_progress(grids, &opts, &stage).with_context(|| input_name.clone())?;
            stage("writing");
            format::writer::write(&output, &brick_file)?;
            for w in &summary.warnings {
                eprintln!("qbricks-bake: warning: {input_name}: {w}");
            }
            #[derive(serde::Serialize)]
            struct Report<'a> {
                #[serde(flatten)]
                summary: &'a BakeSummary,
                seconds: f64,
                output: String,
                warnings: &'a [String],
            }
            let v = serde_json::to_value(Report {
                summary: &summary,
                seconds: start.elapsed().as_secs_f64(),
                output: output.display().to_string(),
                warnings: &summary.warnings,
            })?;
            Ok(serde_json::to_string(&v)?)
        })
    })
}

#[pymodule]
fn _qbricks(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Dataset>()?;
    m.add_function(wrap_pyfunction!(open, m)?)?;
    m.add_function(wrap_pyfunction!(bake, m)?)?;
    m.add("FormatError", m.py().get_type::<FormatError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
