//! `qbricks-bake bake 'in_####.vdb' -o 'out_####.qbk'`: the progress bar and the report;
//! the run is [`qbricks_preprocess::sequence::SequenceBake`]. In an MPI run every rank
//! bakes its share of the frames (balanced by input size) and rank 0 writes the manifest
//! and reports.

use std::io::{IsTerminal, Write};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use files::output::QuietStdout;
use indicatif::{ProgressBar, ProgressStyle};
use qbricks_preprocess::request::BakePlan;
use qbricks_preprocess::sequence::{FrameDone, FramePattern, SequenceBake};
use ranks::Ranks;

use crate::bake::Args;

pub fn run(
    args: &Args,
    input: FramePattern,
    plan: &BakePlan,
    start: Instant,
    ranks: &Ranks,
) -> anyhow::Result<()> {
    let in_pattern = args.input.display().to_string();
    let run = ranks.agree(SequenceBake::prepare(
        &args.input,
        &input,
        args.output.as_deref(),
        args.jobs,
    ))?;
    let mine = ranks.share_files(run.frames.iter().map(|(_, p)| p.as_path()));
    // In a parallel run each rank tells of its own frames in lines, not in a bar.
    let terminal = std::io::stderr().is_terminal() && !ranks.is_parallel();
    let show = !args.quiet && (args.progress || terminal);
    let bar = std::sync::OnceLock::<ProgressBar>::new();
    // Lines on stderr that do not tear the bar.
    let say = |line: String| match bar.get() {
        Some(b) => b.println(line),
        None => eprintln!("{line}"),
    };
    if show && terminal {
        let b = ProgressBar::new(mine.len() as u64);
        b.set_style(
            ProgressStyle::with_template(
                "{elapsed:>4} [{bar:30}] {pos}/{len} frames ({per_sec}, eta {eta}) {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        let _ = bar.set(b);
    }
    let frames = &run.frames;
    if ranks.is_root() && !args.quiet && !run.missing.is_empty() {
        let missing = &run.missing;
        let list: Vec<String> = missing.iter().take(20).map(u64::to_string).collect();
        say(format!(
            "qbricks-bake: warning: {in_pattern}: {} frame(s) missing between {} and {}: {}{}",
            missing.len(),
            frames[0].0,
            frames[frames.len() - 1].0,
            list.join(", "),
            if missing.len() > 20 { ", …" } else { "" }
        ));
    }
    if show && !terminal {
        match ranks.is_parallel() {
            false => say(format!(
                "qbricks-bake: {in_pattern}: {} frames, {} at a time",
                frames.len(),
                run.jobs
            )),
            true => say(format!(
                "qbricks-bake: {in_pattern}: rank {} of {}: {} of {} frames, {} at a time",
                ranks.rank(),
                ranks.size(),
                mine.len(),
                frames.len(),
                run.jobs
            )),
        }
    }
    // Whose progress a line tells, in a parallel run.
    let who = match ranks.is_parallel() {
        true => format!("rank {}: ", ranks.rank()),
        false => String::new(),
    };
    let on_frame = |f: FrameDone| {
        let FrameDone {
            frame,
            input,
            output,
            result,
            done,
            total,
        } = f;
        let name = input.display().to_string();
        match result {
            Ok(summary) if !args.quiet => {
                for w in &summary.warnings {
                    say(format!("qbricks-bake: warning: {name}: {w}"));
                }
            }
            Ok(_) => {}
            Err(e) => {
                // Reader errors start with the file name; others get it here.
                let msg = format!("{e:#}");
                say(match msg.starts_with(&name) {
                    true => format!("qbricks-bake: {msg}"),
                    false => format!("qbricks-bake: {name}: {msg}"),
                });
                if !args.quiet && output.exists() {
                    say(format!(
                        "qbricks-bake: warning: {} is left from an earlier bake; the \
                         manifest lists frame {frame} as failed, so qbricks-view skips it",
                        output.display()
                    ));
                }
            }
        }
        match bar.get() {
            Some(b) => {
                b.set_message(format!("frame {frame}"));
                b.inc(1);
            }
            None if show => eprintln!(
                "qbricks-bake: {who}{:7.2} s  frame {frame} done ({done}/{total})",
                start.elapsed().as_secs_f64(),
            ),
            None => {}
        }
    };
    let never = AtomicBool::new(false);
    let outcomes = run.bake(plan, &mine, &never, &on_frame)?;
    if let Some(b) = bar.get() {
        b.finish_and_clear();
    }
    // Every rank's outcomes at rank 0, which writes the manifest and reports.
    let Some(outcomes) = ranks.gather(&outcomes)? else {
        return Ok(());
    };
    let report = run.finish(outcomes);
    let report = report?;
    let manifest = &report.manifest;
    let seconds = start.elapsed().as_secs_f64();
    // A closed stdout (`… | head`) ends the report quietly; the files are written already.
    let mut out = QuietStdout::new();
    if args.json {
        writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&report.summary(seconds))?
        )?;
    } else if !args.quiet {
        let cells: u64 = manifest.frames.iter().map(|f| f.leaf_cells).sum();
        writeln!(
            out,
            "{in_pattern}: {} of {} frames baked ({} leaf cells, {} at a time) in {seconds:.2} s, {:.2} frames/s; manifest {}",
            manifest.frames.len(),
            report.matched,
            cells,
            report.jobs,
            manifest.frames.len() as f64 / seconds.max(1e-9),
            report.manifest_path.display()
        )?;
        for f in &manifest.fields {
            writeln!(
                out,
                "  {:<12} min {:>12.6e} max {:>12.6e}",
                f.name, f.min, f.max
            )?;
        }
    }
    match report.failure() {
        Some(message) => Err(anyhow::anyhow!(message)),
        None => Ok(()),
    }
}
