//! A bake as a user asks for it — files, and fields named as text — turned into the options
//! of [`crate::bake`] and carried out, the same way for `qbricks-bake` and the Python
//! module (`qbricks.bake`), so that the two make the same file from the same words.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;

use crate::bake::{bake_kept_among, Alone, BakeOptions, BakeSummary, Exchange, DEFAULT_MAX_BRICK};
use crate::derive::Stencil;
use crate::fields::FieldKind;
use crate::inputs::{read_inputs, Layout, ReadError, ReadOptions};
use crate::vdb::VdbFile;

/// What a bake is asked for, in the words of `qbricks-bake bake`'s flags.
#[derive(Debug, Clone)]
pub struct BakeRequest {
    /// `--fields`: q, speed, vorticity, lambda2, helicity, velocity or a scalar grid's
    /// name; `None`: the default (q and speed).
    pub fields: Option<Vec<String>>,
    /// `--grid`: grid names to bake (every grid of that name).
    pub grids: Vec<String>,
    /// `--velocity`: the velocity to bake where the file holds several candidates.
    pub velocity: Vec<String>,
    pub layout: Layout,
    pub stencil: Stencil,
    /// `--max-brick`: largest brick edge in cells.
    pub max_brick: u32,
    /// `--strict`: refuse non-finite values instead of replacing them.
    pub strict: bool,
    /// Worker threads (None: rayon's global pool).
    pub threads: Option<usize>,
    /// `--memory`: the bake's memory budget in bytes (see [`BakeOptions::memory`]).
    pub memory: Option<u64>,
}

impl Default for BakeRequest {
    fn default() -> Self {
        BakeRequest {
            fields: None,
            grids: Vec::new(),
            velocity: Vec::new(),
            layout: Layout::Auto,
            stencil: Stencil::Central,
            max_brick: DEFAULT_MAX_BRICK,
            strict: false,
            threads: None,
            memory: None,
        }
    }
}

/// A field list that names an empty field (`--fields q,,speed`).
#[derive(Debug, thiserror::Error)]
#[error("--fields: empty field name")]
pub struct EmptyFieldName;

/// The read and bake options of a request, checked once and used for every file of a run.
#[derive(Debug, Clone)]
pub struct BakePlan {
    pub read: ReadOptions,
    pub opts: BakeOptions,
}

impl BakePlan {
    /// The plan for each of `jobs` bakes run at once: each has its share of the memory
    /// budget, so that together they keep within it.
    pub fn per_job(&self, jobs: usize) -> BakePlan {
        let mut plan = self.clone();
        plan.opts.memory = self.opts.memory.map(|m| m / jobs.max(1) as u64);
        plan.opts.memory_shared = self.opts.memory.filter(|_| jobs > 1).map(|m| (m, jobs));
        plan
    }
}

impl BakeRequest {
    /// The options every bake of this request uses (the per-file facts, source name and
    /// staggered grids, are filled in by [`bake_file`]).
    pub fn plan(&self) -> Result<BakePlan, EmptyFieldName> {
        let fields = self
            .fields
            .as_ref()
            .map(|list| {
                list.iter()
                    .map(|s| FieldKind::parse_or_grid(s).ok_or(EmptyFieldName))
                    .collect::<Result<Vec<_>, _>>()
            })
            .transpose()?;
        // Scalar grids named as fields are read beside the velocity.
        let extra = fields
            .iter()
            .flatten()
            .filter_map(|k| match k {
                FieldKind::Scalar(n) => Some(n.clone()),
                _ => None,
            })
            .collect();
        Ok(BakePlan {
            read: ReadOptions {
                grids: self.grids.clone(),
                velocity: self.velocity.clone(),
                layout: self.layout,
                extra,
            },
            opts: BakeOptions {
                grids: self.grids.clone(),
                fields,
                stencil: self.stencil,
                max_brick: self.max_brick,
                strict: self.strict,
                threads: self.threads,
                memory: self.memory,
                ..BakeOptions::default()
            },
        })
    }
}

/// The output of a bake of `input` when none is named: the input with extension `.qbk`.
pub fn default_output(input: &Path) -> PathBuf {
    input.with_extension("qbk")
}

/// Bakes `input` to `output` (`None`: [`default_output`]) after checking that the output
/// is not the input (`files::guard`; `flag` is how the user named the output, `-o` or
/// `out`); returns where it wrote and the summary. The one-file bake of the CLI and of
/// the Python module.
pub fn bake_one(
    input: &Path,
    output: Option<&Path>,
    flag: &str,
    plan: &BakePlan,
    stage: &(dyn Fn(&str) + Sync),
    cancel: &AtomicBool,
) -> anyhow::Result<(PathBuf, BakeSummary)> {
    let (output, summary) = bake_one_among(input, output, flag, plan, stage, cancel, &Alone)?;
    Ok((output, summary.expect("a bake in one process writes")))
}

/// As [`bake_one`], shared between `peers` (the ranks of an MPI run, see
/// [`crate::bake::peers`]): rank 0 writes the file and gets its summary, the other ranks `None`.
pub fn bake_one_among(
    input: &Path,
    output: Option<&Path>,
    flag: &str,
    plan: &BakePlan,
    stage: &(dyn Fn(&str) + Sync),
    cancel: &AtomicBool,
    peers: &dyn Exchange,
) -> anyhow::Result<(PathBuf, Option<BakeSummary>)> {
    let (role, output) = match output {
        Some(o) => (flag, o.to_path_buf()),
        None => (
            "the default output (the input with .qbk)",
            default_output(input),
        ),
    };
    files::guard::Guard::new()
        .input("input file", input)
        .output(role, &output)
        .check()?;
    let summary = bake_file_among(input, &output, plan, stage, cancel, peers)?;
    Ok((output, summary))
}

/// A bake stopped by its caller (Ctrl-C in Python) before it wrote anything.
#[derive(Debug, thiserror::Error)]
#[error("cancelled")]
pub struct Cancelled;

/// Reads the grids of `input` that `plan` selects, bakes them (source and staggered grids
/// filled in per file) and writes `output` atomically; `stage` hears each stage's name.
/// `cancel`, when set, stops the bake between stages, before the output is written. The
/// caller has checked that `output` is not an input of the run (`files::guard`).
pub fn bake_file(
    input: &Path,
    output: &Path,
    plan: &BakePlan,
    stage: &(dyn Fn(&str) + Sync),
    cancel: &AtomicBool,
) -> anyhow::Result<BakeSummary> {
    bake_file_among(input, output, plan, stage, cancel, &Alone)
        .map(|s| s.expect("a bake in one process writes"))
}

/// As [`bake_file`], shared between `peers`: rank 0 writes `output` and returns the
/// summary, the other ranks write nothing and return `None`.
pub fn bake_file_among(
    input: &Path,
    output: &Path,
    plan: &BakePlan,
    stage: &(dyn Fn(&str) + Sync),
    cancel: &AtomicBool,
    peers: &dyn Exchange,
) -> anyhow::Result<Option<BakeSummary>> {
    let stopped = || -> anyhow::Result<()> {
        match cancel.load(Ordering::Relaxed) {
            true => Err(Cancelled.into()),
            false => Ok(()),
        }
    };
    let input_name = input.display().to_string();
    let mut opts = plan.opts.clone();
    opts.source = input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Field values kept on disk during the bake go where the output will need the room.
    opts.spill.dir = Some(files::output::staging_dir(output));
    // Read only the grids that will be baked.
    stage("reading VDB");
    let file = VdbFile::open(input)?;
    let (grids, staggered) = match read_inputs(&file, &plan.read) {
        Ok(v) => v,
        // Reader errors already name the file.
        Err(ReadError::Vdb(e)) => return Err(e.into()),
        Err(e) => return Err(anyhow::Error::new(e).context(input_name)),
    };
    opts.staggered = staggered;
    drop(file);
    stopped()?;

    let Some((baked, summary)) =
        bake_kept_among(grids, &opts, stage, peers).with_context(|| input_name.clone())?
    else {
        return Ok(None);
    };
    stopped()?;
    crate::bake::memory::return_freed();
    stage("writing");
    baked.write(output)?;
    Ok(Some(summary))
}

/// A bake's summary as `qbricks-bake --json` prints it: the [`BakeSummary`] with the run's
/// own facts (through a `Value`, so keys print sorted).
pub fn summary_json(
    summary: &BakeSummary,
    seconds: f64,
    output: &Path,
) -> serde_json::Result<serde_json::Value> {
    #[derive(serde::Serialize)]
    struct Report<'a> {
        #[serde(flatten)]
        summary: &'a BakeSummary,
        seconds: f64,
        output: String,
    }
    serde_json::to_value(Report {
        summary,
        seconds,
        output: output.display().to_string(),
    })
}
