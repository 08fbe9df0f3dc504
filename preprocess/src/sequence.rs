//! Frame sequences: `in_####.vdb` baked to `out_####.qbk`, every frame that exists, several
//! at once where memory allows, and a manifest beside the outputs. The patterns and the
//! manifest are shared with `qbricks-view`, so they live in [`format::sequence`] and are
//! re-exported here; the run itself is here so that `qbricks-bake` and the Python module
//! bake a sequence the same way (the same output checks, limits and manifest).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::Context;
pub use format::sequence::*;

use crate::bake::BakeSummary;
use crate::request::{bake_file, default_output, BakePlan, Cancelled};

/// The frame pattern `input` names when it is a sequence: a placeholder (`####`, `%04d`)
/// and no file of that very name (a file with `#` in its name is one file).
pub fn input_pattern(input: &Path) -> Result<Option<FramePattern>, PatternError> {
    Ok(FramePattern::parse(input)?.filter(|_| !input.exists()))
}

/// Peak memory of one frame's bake per byte of its input file, measured on zip-compressed
/// synthetic wakes (≈ 5×) with headroom for files that compress better (half floats,
/// blosc): a guess, only used to keep several frames from exhausting memory.
const BYTES_PER_INPUT_BYTE: u64 = 12;
/// Fixed overhead per frame in the same estimate.
const BYTES_PER_FRAME: u64 = 64 << 20;

/// Frames baked at once: `jobs`, else the thread count, lowered so that the estimated
/// peak of that many frames fits in 80 % of the available memory (at least one).
fn concurrency(jobs: Option<usize>, frames: &[(u64, PathBuf)]) -> usize {
    let n = frames.len().max(1);
    if let Some(j) = jobs {
        return j.clamp(1, n);
    }
    let threads = rayon::current_num_threads().max(1);
    let largest = frames
        .iter()
        .filter_map(|(_, p)| std::fs::metadata(p).ok().map(|m| m.len()))
        .max()
        .unwrap_or(0);
    let per_frame = largest
        .saturating_mul(BYTES_PER_INPUT_BYTE)
        .saturating_add(BYTES_PER_FRAME);
    let by_memory = files::limits::available_memory().map_or(usize::MAX, |m| {
        usize::try_from(m / 10 * 8 / per_frame).unwrap_or(usize::MAX)
    });
    threads.min(by_memory).clamp(1, n)
}

/// One frame's outcome, as the manifest lists it.
pub type FrameOutcome = Result<ManifestFrame, ManifestFailure>;

/// What a sequence bake tells its caller as each frame is done.
pub struct FrameDone<'a> {
    pub frame: u64,
    pub input: &'a Path,
    pub output: &'a Path,
    pub result: &'a anyhow::Result<BakeSummary>,
    /// Frames done so far (of this call), and how many it bakes.
    pub done: usize,
    pub total: usize,
}

/// A finished sequence bake: the manifest written, and where.
pub struct SequenceReport {
    pub manifest: Manifest,
    pub manifest_path: PathBuf,
    /// Frames that matched the pattern.
    pub matched: usize,
    pub jobs: usize,
}

impl SequenceReport {
    /// The run's summary (`qbricks-bake --json` of a sequence), `seconds` after its start.
    pub fn summary(&self, seconds: f64) -> serde_json::Value {
        let m = &self.manifest;
        serde_json::json!({
            "frames": m.frames.len(),
            "failed": m.failed.iter().map(|f| f.frame).collect::<Vec<_>>(),
            "missing": m.missing.len(),
            "leaf_cells": m.frames.iter().map(|f| f.leaf_cells).sum::<u64>(),
            "jobs": self.jobs,
            "seconds": seconds,
            "fields": m.fields,
            "manifest": self.manifest_path.display().to_string(),
        })
    }

    /// The error a run with failed frames ends with (after its report), naming them.
    pub fn failure(&self) -> Option<String> {
        if self.manifest.failed.is_empty() {
            return None;
        }
        let list: Vec<&str> = self
            .manifest
            .failed
            .iter()
            .map(|f| f.input.as_str())
            .collect();
        Some(format!(
            "{}: {} of {} frames failed: {}",
            self.manifest.input_pattern,
            list.len(),
            self.matched,
            list.join(", ")
        ))
    }
}

/// A sequence bake, checked and ready: the frames that match the input pattern, where each
/// goes, and how many to bake at once. Made by [`SequenceBake::prepare`], run by
/// [`SequenceBake::bake`] (all its frames, or one process's share of them in a
/// frame-parallel run) and ended by [`SequenceBake::finish`], which writes the manifest.
pub struct SequenceBake {
    in_pattern: String,
    out_path: PathBuf,
    out: FramePattern,
    /// The frames that exist, by number, with their input files.
    pub frames: Vec<(u64, PathBuf)>,
    /// Numbers absent between the first frame and the last.
    pub missing: Vec<u64>,
    /// Frames baked at once.
    pub jobs: usize,
}

impl SequenceBake {
    /// Lists the frames matching `input` (`input_text` as the user wrote it) and checks the
    /// run: `output` a frame pattern too (`None`: the input's with `.qbk`), the frame count
    /// within bounds, every output against every input frame (before any frame is baked),
    /// its directory made. `jobs`: frames at once (default: see [`concurrency`]).
    pub fn prepare(
        input_text: &Path,
        input: &FramePattern,
        output: Option<&Path>,
        jobs: Option<usize>,
    ) -> anyhow::Result<SequenceBake> {
        let in_pattern = input_text.display().to_string();
        let out_path = output.map_or_else(|| default_output(input_text), Path::to_path_buf);
        let out = match output {
            Some(o) => FramePattern::parse(o)?.ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: the input is a frame pattern, so the output must be one too (e.g. out/frame_####.qbk)",
                    o.display()
                )
            })?,
            None => FramePattern::parse(&out_path)?
                .context("the default output lost the frame pattern")?,
        };
        let frames = input
            .scan()
            .with_context(|| format!("{in_pattern}: cannot list {}", input.dir().display()))?;
        if frames.is_empty() {
            anyhow::bail!("{in_pattern}: no file matches the frame pattern");
        }
        files::limits::count("frames", frames.len() as u64, 1, files::limits::MAX_FRAMES)?;
        // Every output against every input frame before any frame is baked: `-o
        // 'f_1###.vdb'` names input frame 1001 as the output of frame 1.
        let mut guard = files::guard::Guard::new();
        for (frame, path) in &frames {
            guard.input(format!("frame {frame}"), path);
        }
        for (frame, _) in &frames {
            guard.output(format!("-o (frame {frame})"), &out.path(*frame));
        }
        guard.output("the manifest", &out.manifest_path());
        guard.check()?;
        if !out.dir().as_os_str().is_empty() {
            std::fs::create_dir_all(out.dir())
                .with_context(|| format!("{}: cannot create the directory", out.dir().display()))?;
        }
        let numbers: Vec<u64> = frames.iter().map(|f| f.0).collect();
        let missing = gaps(&numbers);
        let jobs = concurrency(jobs, &frames);
        Ok(SequenceBake {
            in_pattern,
            out_path,
            out,
            frames,
            missing,
            jobs,
        })
    }

    /// Bakes the frames `which` (indices into [`SequenceBake::frames`]), `jobs` at once,
    /// each with its share of the plan's memory budget; a frame that fails is an outcome
    /// like the others and the run goes on. `cancel` stops the run before the next frame
    /// ([`Cancelled`]; frames written stay, whole).
    pub fn bake(
        &self,
        plan: &BakePlan,
        which: &[usize],
        cancel: &AtomicBool,
        on_frame: &(dyn Fn(FrameDone) + Sync),
    ) -> Result<Vec<FrameOutcome>, Cancelled> {
        // Workers take the next frame from a counter; each bake uses the shared rayon
        // pool, so frames overlap their sequential parts (reading, writing) and share the
        // threads.
        let workers = self.jobs.min(which.len()).max(1);
        let plan = &plan.per_job(workers);
        let next = AtomicUsize::new(0);
        let results: Mutex<Vec<Option<FrameOutcome>>> = Mutex::new(vec![None; which.len()]);
        let done = AtomicUsize::new(0);
        std::thread::scope(|scope| {
            for _ in 0..workers {
                scope.spawn(|| loop {
                    if cancel.load(Ordering::Relaxed) {
                        break;
                    }
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some((frame, path)) = which.get(k).and_then(|&i| self.frames.get(i)) else {
                        break;
                    };
                    let output = self.out.path(*frame);
                    let result = bake_file(path, &output, plan, &|_| {}, cancel);
                    if result.as_ref().is_err_and(|e| e.is::<Cancelled>()) {
                        break;
                    }
                    let entry = manifest_entry(*frame, path, &output, &result);
                    if let Ok(mut r) = results.lock() {
                        r[k] = Some(entry);
                    }
                    on_frame(FrameDone {
                        frame: *frame,
                        input: path,
                        output: &output,
                        result: &result,
                        done: done.fetch_add(1, Ordering::Relaxed) + 1,
                        total: which.len(),
                    });
                });
            }
        });
        if cancel.load(Ordering::Relaxed) {
            return Err(Cancelled);
        }
        // A worker that panicked poisons the lock; its frames are then missing, not lost
        // silently: they are listed as failed by `finish`.
        let results = results.into_inner().unwrap_or_else(|e| e.into_inner());
        Ok(results.into_iter().flatten().collect())
    }

    /// Writes the manifest of `outcomes` (every frame's, in any order; a frame that matched
    /// but has none is listed as failed) and returns the run's report.
    pub fn finish(self, outcomes: Vec<FrameOutcome>) -> anyhow::Result<SequenceReport> {
        let mut baked = Vec::new();
        let mut failed = Vec::new();
        for r in outcomes {
            match r {
                Ok(f) => baked.push(f),
                Err(f) => failed.push(f),
            }
        }
        let known: std::collections::HashSet<u64> = baked
            .iter()
            .map(|f| f.frame)
            .chain(failed.iter().map(|f| f.frame))
            .collect();
        for (frame, path) in &self.frames {
            if !known.contains(frame) {
                failed.push(ManifestFailure {
                    frame: *frame,
                    input: path.display().to_string(),
                    error: "not baked: its worker stopped".to_string(),
                });
            }
        }
        baked.sort_by_key(|f| f.frame);
        failed.sort_by_key(|f| f.frame);
        let manifest = Manifest {
            input_pattern: self.in_pattern,
            output_pattern: self.out_path.display().to_string(),
            fields: global_ranges(&baked),
            frames: baked,
            failed,
            missing: self.missing,
        };
        let manifest_path = self.out.manifest_path();
        write_manifest(&manifest_path, &manifest)?;
        Ok(SequenceReport {
            manifest,
            manifest_path,
            matched: self.frames.len(),
            jobs: self.jobs,
        })
    }
}

/// Bakes every frame matching `input` to `output` in this process and writes the manifest
/// (see [`SequenceBake`]; `Cancelled` when `cancel` stopped it, and then no manifest is
/// written).
pub fn bake_sequence(
    input_text: &Path,
    input: &FramePattern,
    output: Option<&Path>,
    plan: &BakePlan,
    jobs: Option<usize>,
    cancel: &AtomicBool,
    on_frame: &(dyn Fn(FrameDone) + Sync),
) -> anyhow::Result<SequenceReport> {
    let run = SequenceBake::prepare(input_text, input, output, jobs)?;
    let all: Vec<usize> = (0..run.frames.len()).collect();
    let outcomes = run.bake(plan, &all, cancel, on_frame)?;
    run.finish(outcomes)
}

/// The manifest's line for one frame's outcome.
fn manifest_entry(
    frame: u64,
    input: &Path,
    output: &Path,
    result: &anyhow::Result<BakeSummary>,
) -> Result<ManifestFrame, ManifestFailure> {
    let name = input.display().to_string();
    match result {
        Ok(summary) => Ok(ManifestFrame {
            frame,
            input: name,
            output: output.display().to_string(),
            leaf_cells: summary.leaf_cells,
            fields: summary
                .fields
                .iter()
                .map(|f| FieldRange {
                    name: f.name.clone(),
                    min: f.min,
                    max: f.max,
                })
                .collect(),
        }),
        Err(e) => Err(ManifestFailure {
            frame,
            input: name,
            error: format!("{e:#}"),
        }),
    }
}

fn write_manifest(path: &Path, manifest: &Manifest) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(manifest)?;
    files::output::write_atomic(path, |out| {
        out.write_all(text.as_bytes())?;
        out.write_all(b"\n")
    })
    .with_context(|| format!("{}: cannot write the manifest", path.display()))?;
    Ok(())
}
