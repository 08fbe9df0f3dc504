//! `qbricks-lab accuracy`: the analytic flows baked at several resolutions against their
//! exact Q, speed, vorticity and λ2.

use std::io::Write;
use std::path::PathBuf;

use anyhow::bail;
use files::output::QuietStdout;
use indicatif::{ProgressBar, ProgressStyle};
use lab::accuracy::{accuracy, AccuracyOptions, AccuracyReport, ErrorStats};
use preprocess::derive::Stencil;

/// `--stencil`, as `qbricks-bake bake` spells it.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum StencilArg {
    /// Central differences; one-sided at grid edges and next to missing cells.
    Central,
    /// Central differences; at grid edges the neighbour velocity comes from the
    /// reconstructed multi-level field.
    CrossLevel,
}

#[derive(clap::Args)]
pub struct Args {
    /// Scene: wake, wake-single, lamb-oseen, burgers, abc, or lamb-oseen-nested,
    /// burgers-nested, abc-nested (nested boxes: errors across level boundaries).
    pub scene: String,
    /// Coarsest-grid resolutions to bake (in memory), e.g. `--n0 32 64`.
    #[arg(long, num_args = 1.., default_values_t = [32u32, 64])]
    pub n0: Vec<u32>,
    /// Nested levels of the wake and the -nested scenes (single-grid scenes ignore it).
    #[arg(long, default_value_t = 3)]
    pub levels: u32,
    /// Stencil of the velocity gradient.
    #[arg(long, value_enum, default_value_t = StencilArg::Central)]
    pub stencil: StencilArg,
    /// Random points for each reconstruction check.
    #[arg(long, default_value_t = 20_000)]
    pub points: usize,
    /// Iso value of the surface checks [default: 0.05 for the wakes, else a fifth of the
    /// largest exact Q].
    #[arg(long)]
    pub iso: Option<f64>,
    /// The surface checks cast RAYS×RAYS camera rays with the viewer's `exact` strategy.
    #[arg(long, default_value_t = 128)]
    pub rays: u32,
    /// Fields baked and compared, comma separated: q (always), speed, vorticity, lambda2.
    /// Fewer fields make a smaller archive (it must stay under 2 GiB).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "q,speed,vorticity,lambda2"
    )]
    pub fields: Vec<String>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Draw the relative RMS errors against the finest cell width (log axes) to this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.n0.iter().any(|&n| !(4..=1024).contains(&n)) {
        bail!("--n0: expected values in 4..=1024, found {:?}", args.n0);
    }
    if args.points == 0 || args.points > 10_000_000 {
        bail!("--points: expected 1..=10000000, found {}", args.points);
    }
    if !(1..=4096).contains(&args.rays) {
        bail!("--rays: expected 1..=4096, found {}", args.rays);
    }
    if args.iso.is_some_and(|v| !v.is_finite()) {
        bail!("--iso: expected a finite number");
    }
    let opts = AccuracyOptions {
        scene: args.scene.clone(),
        n0: args.n0.clone(),
        levels: args.levels,
        stencil: match args.stencil {
            StencilArg::Central => Stencil::Central,
            StencilArg::CrossLevel => Stencil::CrossLevel,
        },
        points: args.points,
        iso: args.iso,
        rays: args.rays,
        fields: args.fields.iter().map(|f| f.trim().to_string()).collect(),
        ..AccuracyOptions::default()
    };
    let bar = ProgressBar::with_draw_target(
        Some(args.n0.len() as u64),
        indicatif::ProgressDrawTarget::stderr(),
    );
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} bakes, {elapsed} {msg}") {
        bar.set_style(style);
    }
    let mut started = 0;
    let report = accuracy(&opts, &mut |n0| {
        if started > 0 {
            bar.inc(1);
        }
        started += 1;
        bar.set_message(format!("n0 {n0}"));
    });
    bar.finish_and_clear();
    let report = report?;
    if let Some(p) = &args.plot {
        lab::accuracy::save_plot(p, &report)?;
    }
    let mut out = QuietStdout::new();
    if args.json {
        writeln!(out, "{}", serde_json::to_string(&report)?)?;
    } else {
        write_text(&mut out, &report)?;
    }
    Ok(())
}

fn write_text(out: &mut impl Write, r: &AccuracyReport) -> std::io::Result<()> {
    let e = |s: &ErrorStats| format!("{:.2e} / {:.2e}", s.rms_rel, s.max_rel);
    // A reconstruction check that had no points (no level boundary) prints a dash.
    let e_or_dash = |s: &ErrorStats| {
        if s.points > 0 {
            e(s)
        } else {
            "-".to_string()
        }
    };
    writeln!(
        out,
        "scene {}, stencil {}; errors are RMS / max relative to p99 of the exact |value|",
        r.scene, r.stencil
    )?;
    for res in &r.resolutions {
        writeln!(
            out,
            "n0 {:>4}: h {:.5}, {} leaf cells, p99 |Q| {:.3e}, speed {:.3e}, |vorticity| {:.3e}, |lambda2| {:.3e}",
            res.n0,
            res.finest_width,
            res.leaf_cells,
            res.q_scale,
            res.speed_scale,
            res.vorticity_scale,
            res.lambda2_scale
        )?;
        let reconstructed = format!("reconstructed ({})", res.reconstructed_q.points);
        writeln!(
            out,
            "  {:<10} {:<21} {:<21} near level boundaries ({})",
            "field", "stored", reconstructed, res.boundary_q.points
        )?;
        let rows: [(&str, &ErrorStats, Option<&ErrorStats>, Option<&ErrorStats>); 4] = [
            (
                "Q",
                &res.stored_q,
                Some(&res.reconstructed_q),
                Some(&res.boundary_q),
            ),
            ("speed", &res.stored_speed, None, None),
            (
                "vorticity",
                &res.stored_vorticity,
                Some(&res.reconstructed_vorticity),
                Some(&res.boundary_vorticity),
            ),
            (
                "lambda2",
                &res.stored_lambda2,
                Some(&res.reconstructed_lambda2),
                Some(&res.boundary_lambda2),
            ),
        ];
        for (name, stored, rec, near) in rows {
            if stored.points == 0 {
                // Not measured (--fields).
                continue;
            }
            writeln!(
                out,
                "  {:<10} {:<21} {:<21} {}",
                name,
                e(stored),
                rec.map_or("-".to_string(), e_or_dash),
                near.map_or("-".to_string(), e_or_dash)
            )?;
        }
        for l in &res.levels {
            let mut line = format!(
                "    level {} (h {:.5}, {} cells): Q {}",
                l.level,
                l.cell_width,
                l.q.points,
                e(&l.q)
            );
            for (name, s) in [
                ("speed", &l.speed),
                ("vorticity", &l.vorticity),
                ("lambda2", &l.lambda2),
            ] {
                if s.points > 0 {
                    line += &format!("   {name} {}", e(s));
                }
            }
            writeln!(out, "{line}")?;
        }
        let s = &res.surface;
        writeln!(
            out,
            "  iso Q = {:.4}, {} exact hits of {} rays: position RMS / max {:.2e} / {:.2e} cells, normal angle RMS / max {:.3}° / {:.3}°",
            s.iso,
            s.hits,
            s.rays,
            s.position.rms_rel,
            s.position.max_rel,
            s.normal_deg.rms,
            s.normal_deg.max
        )?;
    }
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    for o in &r.orders {
        writeln!(out, "order n0 {} → {}:", o.n0_coarse, o.n0_fine)?;
        writeln!(
            out,
            "  {:<10} {:<17} {:<15} near level boundaries",
            "field", "stored rms (max)", "reconstructed"
        )?;
        let with_max = |rms: Option<f64>, max: Option<f64>| match (rms, max) {
            (Some(r), Some(m)) => Some(format!("{r:.2} ({m:.2})")),
            _ => None,
        };
        let rows = [
            (
                "Q",
                Some(format!("{:.2} ({:.2})", o.stored_q_rms, o.stored_q_max)),
                opt(Some(o.reconstructed_q_rms)),
                opt(o.boundary_q_rms),
            ),
            (
                "speed",
                o.stored_speed_rms.map(|v| format!("{v:.2}")),
                "-".to_string(),
                "-".to_string(),
            ),
            (
                "vorticity",
                with_max(o.stored_vorticity_rms, o.stored_vorticity_max),
                opt(o.reconstructed_vorticity_rms),
                opt(o.boundary_vorticity_rms),
            ),
            (
                "lambda2",
                with_max(o.stored_lambda2_rms, o.stored_lambda2_max),
                opt(o.reconstructed_lambda2_rms),
                opt(o.boundary_lambda2_rms),
            ),
        ];
        for (name, stored, rec, near) in rows {
            // A field not measured (--fields) has no stored order.
            let Some(stored) = stored else { continue };
            writeln!(out, "  {name:<10} {stored:<17} {rec:<15} {near}")?;
        }
        if let (Some(p), Some(n)) = (o.surface_position_rms, o.normal_angle_rms) {
            writeln!(
                out,
                "  iso-surface position rms {p:.2}, normal angle rms {n:.2}"
            )?;
        }
    }
    Ok(())
}
