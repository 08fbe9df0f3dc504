//! `qbricks-bake bake 'in_####.vdb' -o 'out_####.qbk'`: every frame that exists, several
//! at once where memory allows, one progress bar, a manifest next to the outputs.

use std::io::{IsTerminal, Write};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::Context;
use files::output::QuietStdout;
use indicatif::{ProgressBar, ProgressStyle};
use qbricks_preprocess::bake::BakeOptions;
use qbricks_preprocess::inputs::ReadOptions;
use qbricks_preprocess::sequence::{
    gaps, global_ranges, FieldRange, FramePattern, Manifest, ManifestFailure, ManifestFrame,
};

use crate::bake::{bake_file, Args};

/// Peak memory of one frame's bake per byte of its input file, measured on zip-compressed
/// synthetic wakes (≈ 5×) with headroom for files that compress better (half floats,
/// blosc): a guess, only used to keep several frames from exhausting memory.
const BYTES_PER_INPUT_BYTE: u64 = 12;
/// Fixed overhead per frame in the same estimate.
const BYTES_PER_FRAME: u64 = 64 << 20;

/// Frames baked at once: `--jobs`, else the thread count, lowered so that the estimated
/// peak of that many frames fits in 80 % of the available memory (at least one).
fn concurrency(jobs: Option<usize>, frames: &[(u64, std::path::PathBuf)]) -> usize {
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

pub fn run(
    args: &Args,
    input: FramePattern,
    opts: &BakeOptions,
    read: &ReadOptions,
    start: Instant,
) -> anyhow::Result<()> {
    let in_pattern = args.input.display().to_string();
    let output = match &args.output {
        Some(o) => FramePattern::parse(o)?.ok_or_else(|| {
            anyhow::anyhow!(
                "{}: the input is a frame pattern, so the output must be one too (e.g. out/frame_####.qbk)",
                o.display()
            )
        })?,
        None => FramePattern::parse(&args.input.with_extension("qbk"))?
            .context("the default output lost the frame pattern")?,
    };
    let out_pattern = args
        .output
        .clone()
        .unwrap_or_else(|| args.input.with_extension("qbk"))
        .display()
        .to_string();
    let frames = input
        .scan()
        .with_context(|| format!("{in_pattern}: cannot list {}", input.dir().display()))?;
    if frames.is_empty() {
        anyhow::bail!("{in_pattern}: no file matches the frame pattern");
    }
    files::limits::count("frames", frames.len() as u64, 1, files::limits::MAX_FRAMES)?;
    // Every output against every input frame before any frame is baked: `-o 'f_1###.vdb'`
    // names input frame 1001 as the output of frame 1.
    let mut guard = files::guard::Guard::new();
    for (frame, path) in &frames {
        guard.input(format!("frame {frame}"), path);
    }
    for (frame, _) in &frames {
        guard.output(format!("-o (frame {frame})"), &output.path(*frame));
    }
    guard.output("the manifest", &output.manifest_path());
    guard.check()?;
    if !output.dir().as_os_str().is_empty() {
        std::fs::create_dir_all(output.dir())
            .with_context(|| format!("{}: cannot create the directory", output.dir().display()))?;
    }
    let numbers: Vec<u64> = frames.iter().map(|f| f.0).collect();
    let missing = gaps(&numbers);
    let jobs = concurrency(args.jobs, &frames);

    let terminal = std::io::stderr().is_terminal();
    let show = !args.quiet && (args.progress || terminal);
    let bar = (show && terminal).then(|| {
        let b = ProgressBar::new(frames.len() as u64);
        b.set_style(
            ProgressStyle::with_template(
                "{elapsed:>4} [{bar:30}] {pos}/{len} frames ({per_sec}, eta {eta}) {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        b
    });
    // Lines on stderr that do not tear the bar.
    let say = |line: String| match &bar {
        Some(b) => b.println(line),
        None => eprintln!("{line}"),
    };
    if !args.quiet && !missing.is_empty() {
        let list: Vec<String> = missing.iter().take(20).map(u64::to_string).collect();
        say(format!(
            "qbricks-bake: warning: {in_pattern}: {} frame(s) missing between {} and {}: {}{}",
            missing.len(),
            numbers[0],
            numbers[numbers.len() - 1],
            list.join(", "),
            if missing.len() > 20 { ", …" } else { "" }
        ));
    }
    if show && !terminal {
        say(format!(
            "qbricks-bake: {in_pattern}: {} frames, {jobs} at a time",
            frames.len()
        ));
    }

    // Workers take the next frame from a counter; each bake uses the shared rayon pool, so
    // frames overlap their sequential parts (reading, writing) and share the threads.
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<ManifestFrame, ManifestFailure>>>> =
        Mutex::new(vec![None; frames.len()]);
    let done = AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some((frame, path)) = frames.get(i) else {
                    break;
                };
                let out = output.path(*frame);
                let result = bake_file(path, &out, opts, read, &|_| {});
                let name = path.display().to_string();
                let entry = match result {
                    Ok(summary) => {
                        if !args.quiet {
                            for w in &summary.warnings {
                                say(format!("qbricks-bake: warning: {name}: {w}"));
                            }
                        }
                        Ok(ManifestFrame {
                            frame: *frame,
                            input: name.clone(),
                            output: out.display().to_string(),
                            leaf_cells: summary.leaf_cells,
                            fields: summary
                                .fields
                                .into_iter()
                                .map(|f| FieldRange {
                                    name: f.name,
                                    min: f.min,
                                    max: f.max,
                                })
                                .collect(),
                        })
                    }
                    Err(e) => {
                        // Reader errors start with the file name; others get it here.
                        let msg = format!("{e:#}");
                        let line = if msg.starts_with(&name) {
                            msg.clone()
                        } else {
                            format!("{name}: {msg}")
                        };
                        say(format!("qbricks-bake: {line}"));
                        if !args.quiet && out.exists() {
                            say(format!(
                                "qbricks-bake: warning: {} is left from an earlier bake; the \
                                 manifest lists frame {frame} as failed, so qbricks-view skips it",
                                out.display()
                            ));
                        }
                        Err(ManifestFailure {
                            frame: *frame,
                            input: name.clone(),
                            error: msg,
                        })
                    }
                };
                if let Ok(mut r) = results.lock() {
                    r[i] = Some(entry);
                }
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                match &bar {
                    Some(b) => {
                        b.set_message(format!("frame {frame}"));
                        b.inc(1);
                    }
                    None if show => eprintln!(
                        "qbricks-bake: {:7.2} s  frame {frame} done ({n}/{})",
                        start.elapsed().as_secs_f64(),
                        frames.len()
                    ),
                    None => {}
                }
            });
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let results = results
        .into_inner()
        .map_err(|_| anyhow::anyhow!("a frame worker panicked"))?;
    let mut baked = Vec::new();
    let mut failed = Vec::new();
    for r in results.into_iter().flatten() {
        match r {
            Ok(f) => baked.push(f),
            Err(f) => failed.push(f),
        }
    }
    let manifest = Manifest {
        input_pattern: in_pattern.clone(),
        output_pattern: out_pattern,
        fields: global_ranges(&baked),
        frames: baked,
        failed,
        missing,
    };
    let manifest_path = output.manifest_path();
    write_manifest(&manifest_path, &manifest)?;
    let seconds = start.elapsed().as_secs_f64();
    let cells: u64 = manifest.frames.iter().map(|f| f.leaf_cells).sum();
    // A closed stdout (`… | head`) ends the report quietly; the files are written already.
    let mut out = QuietStdout::new();
    if args.json {
        let v = serde_json::json!({
            "frames": manifest.frames.len(),
            "failed": manifest.failed.iter().map(|f| f.frame).collect::<Vec<_>>(),
            "missing": manifest.missing.len(),
            "leaf_cells": cells,
            "jobs": jobs,
            "seconds": seconds,
            "fields": manifest.fields,
            "manifest": manifest_path.display().to_string(),
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&v)?)?;
    } else if !args.quiet {
        writeln!(
            out,
            "{in_pattern}: {} of {} frames baked ({} leaf cells, {} at a time) in {seconds:.2} s, {:.2} frames/s; manifest {}",
            manifest.frames.len(),
            frames.len(),
            cells,
            jobs,
            manifest.frames.len() as f64 / seconds.max(1e-9),
            manifest_path.display()
        )?;
        for f in &manifest.fields {
            writeln!(
                out,
                "  {:<12} min {:>12.6e} max {:>12.6e}",
                f.name, f.min, f.max
            )?;
        }
    }
    if !manifest.failed.is_empty() {
        let list: Vec<String> = manifest.failed.iter().map(|f| f.input.clone()).collect();
        anyhow::bail!(
            "{in_pattern}: {} of {} frames failed: {}",
            list.len(),
            frames.len(),
            list.join(", ")
        );
    }
    Ok(())
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
