//! Measurement (ignored by default): shading normals on the synthetic wake against the
//! exact gradient of Q, smooth (central differences of the reconstruction) against the
//! analytic gradient of the reconstruction, and the render time of both, in one run.
//!
//! `cargo build --release --workspace`, then
//! `cargo test --release --test cross_crate shading_wake -- --ignored --nocapture`

use crate::common;
use std::time::Instant;

use viewer::dataset::Dataset;
use viewer::mesh::DVec3;
use viewer::mesh::Meshes;
use viewer::ray::{RayCaster, Shading};
use viewer::render::{render, Scene};
use viewer::sampling::Strategy;
use viewer::view_state::{Overrides, ViewState};

fn angle_deg(a: DVec3, b: DVec3) -> f64 {
    a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
}

fn pct(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q) as usize]
}

/// CPU time of this process in ms (user + system, all threads), from `/proc/self/stat`;
/// NaN where that is not available. Less sensitive than wall time to other jobs on the
/// machine, which is where these measurements are usually taken.
fn cpu_ms() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the parenthesised command name; utime and stime are the 14th and 15th.
    let Some(rest) = stat.rsplit(')').next() else {
        return f64::NAN;
    };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok());
    match (ticks(11), ticks(12)) {
        // Linux reports them in USER_HZ, which is 100 on every platform it runs on.
        (Some(u), Some(s)) => (u + s) * 10.0,
        _ => f64::NAN,
    }
}

#[test]
#[ignore = "measurement: prints normal errors and render times on the n0 = 64 wake"]
fn measure_shading_normals_on_the_wake() {
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("wake64.vdb");
    let qbk = dir.path().join("wake64.qbk");
    let bake = common::bin("qbricks-bake");
    let ok = std::process::Command::new(common::bin("qbricks-lab"))
        .args(["synth", "wake", "--n0", "64", "-o"])
        .arg(&vdb)
        .status()
        .expect("synth")
        .success();
    assert!(ok);
    let ok = std::process::Command::new(&bake)
        .arg("bake")
        .arg(&vdb)
        .arg("-o")
        .arg(&qbk)
        .arg("--quiet")
        .status()
        .expect("bake")
        .success();
    assert!(ok);
    let ds = Dataset::open(&qbk).expect("open");
    let vol = ds.volume();
    let flow = lab::analytic::scene("wake").expect("wake flow");
    let mut st = ViewState::default_for_volume(vol);
    Overrides {
        iso: Some(0.05.into()),
        eye: Some("0.5,2.2,3.6".into()),
        look_at: Some("2.2,0,0".into()),
        width: Some(512),
        height: Some(512),
        strategy: Some(Strategy::Exact),
        ..Overrides::default()
    }
    .apply(&mut st, false)
    .expect("flags");
    let meshes = Meshes::empty();
    // Exact ∇Q by central differences of the analytic Q (h far below the cell width).
    let grad_q = |p: DVec3| -> DVec3 {
        let h = 1e-5;
        let d = |a: DVec3| {
            (flow.q((p + h * a).to_array()) - flow.q((p - h * a).to_array())) / (2.0 * h)
        };
        DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z))
    };
    for shading in [Shading::Analytic, Shading::Smooth] {
        let mut scene = Scene::new(vol, &st, &meshes).expect("scene");
        scene.shading = shading;
        let mut caster = RayCaster::new(&scene);
        let (w, h) = (st.width as usize, st.height as usize);
        let mut px: Vec<Option<(DVec3, DVec3)>> = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (ray, jit) = caster.camera_ray(x as u32, y as u32, 0);
                px.push(caster.surface(&ray, jit).and_then(|s| {
                    let g = grad_q(s.world);
                    let mut e = g.try_normalize()?;
                    if e.dot(ray.dir) > 0.0 {
                        e = -e;
                    }
                    Some((s.normal, e))
                }));
            }
        }
        let errs: Vec<f64> = px
            .iter()
            .flatten()
            .map(|(n, e)| angle_deg(*n, *e))
            .collect();
        let (mut nb, mut nb_exact) = (Vec::new(), Vec::new());
        for y in 0..h {
            for x in 0..w {
                let Some((n0, e0)) = px[y * w + x] else {
                    continue;
                };
                for (dx, dy) in [(1, 0), (0, 1)] {
                    if x + dx >= w || y + dy >= h {
                        continue;
                    }
                    if let Some((n1, e1)) = px[(y + dy) * w + x + dx] {
                        nb.push(angle_deg(n0, n1));
                        nb_exact.push(angle_deg(e0, e1));
                    }
                }
            }
        }
        println!(
            "{shading:?}: {} hits, angle to exact ∇Q mean {:.2}° p90 {:.2}°; neighbour angle p99 {:.2}° (exact normals' own p99 {:.2}°); ",
            errs.len(),
            errs.iter().sum::<f64>() / errs.len().max(1) as f64,
            pct(&errs, 0.9),
            pct(&nb, 0.99),
            pct(&nb_exact, 0.99),
        );
    }
    // Render times of the whole frame, the two shadings interleaved (A, S, A, S, …) so a
    // change in machine load hits both alike; median of 15 each.
    let scenes: Vec<Scene> = [Shading::Analytic, Shading::Smooth]
        .into_iter()
        .map(|shading| {
            let mut scene = Scene::new(vol, &st, &meshes).expect("scene");
            scene.shading = shading;
            scene
        })
        .collect();
    let mut times = vec![Vec::new(); scenes.len()];
    let mut cpu = vec![Vec::new(); scenes.len()];
    for _ in 0..15 {
        for ((scene, t), c) in scenes.iter().zip(&mut times).zip(&mut cpu) {
            let (start, cpu_start) = (Instant::now(), cpu_ms());
            let _ = render(scene);
            t.push(start.elapsed().as_secs_f64() * 1e3);
            c.push(cpu_ms() - cpu_start);
        }
    }
    for ((scene, t), c) in scenes.iter().zip(&mut times).zip(&mut cpu) {
        t.sort_by(f64::total_cmp);
        c.sort_by(f64::total_cmp);
        println!(
            "{:?}: render {:.1} ms wall (median of 15, interleaved; min {:.1}, max {:.1}), \
             {:.0} ms CPU (median; min {:.0})",
            scene.shading, t[7], t[0], t[14], c[7], c[0]
        );
    }
}
