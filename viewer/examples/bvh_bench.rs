//! Times the mesh BVH: build and ray queries against an icosphere of 20·4^S triangles.
//! Prints numbers only (no assertions); rays are deterministic.
//!
//! `cargo run --release -p qbricks-viewer --example bvh_bench [-- SUBDIVISIONS]`

use std::time::Instant;

use qbricks_viewer::camera::Ray;
use qbricks_viewer::mesh::{icosphere, DVec3, Meshes};

fn main() -> anyhow::Result<()> {
    let s: u32 = match std::env::args().nth(1) {
        Some(a) => a
            .parse()
            .map_err(|e| anyhow::anyhow!("SUBDIVISIONS `{a}`: {e}"))?,
        None => 6,
    };
    anyhow::ensure!(s <= 8, "SUBDIVISIONS: expected 0..=8, found {s}");
    let sphere = icosphere(DVec3::ZERO, 0.5, s);
    let t = Instant::now();
    let meshes = Meshes::from_meshes(&[sphere]);
    let build_ms = t.elapsed().as_secs_f64() * 1e3;

    // 1M rays from a 1000x1000 grid on a plane in front of the sphere, aimed at it.
    let n = 1000u32;
    let (mut hits, mut occluded) = (0u64, 0u64);
    let t = Instant::now();
    for j in 0..n {
        for i in 0..n {
            let x = (f64::from(i) + 0.5) / f64::from(n) * 1.2 - 0.6;
            let y = (f64::from(j) + 0.5) / f64::from(n) * 1.2 - 0.6;
            let ray = Ray {
                origin: DVec3::new(x, y, 3.0),
                dir: DVec3::new(-0.1 * x, -0.1 * y, -1.0).normalize(),
            };
            if meshes.intersect(&ray, 0.0, f64::INFINITY).is_some() {
                hits += 1;
            }
        }
    }
    let nearest_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    for j in 0..n {
        for i in 0..n {
            let x = (f64::from(i) + 0.5) / f64::from(n) * 1.2 - 0.6;
            let y = (f64::from(j) + 0.5) / f64::from(n) * 1.2 - 0.6;
            let ray = Ray {
                origin: DVec3::new(x, y, 3.0),
                dir: DVec3::new(-0.1 * x, -0.1 * y, -1.0).normalize(),
            };
            if meshes.occluded(&ray, 0.0, f64::INFINITY) {
                occluded += 1;
            }
        }
    }
    let any_s = t.elapsed().as_secs_f64();
    let rays = f64::from(n * n);
    println!(
        "triangles {}  build {build_ms:.1} ms  nearest {:.2} Mrays/s (hit {:.3})  occluded {:.2} Mrays/s ({:.3})",
        meshes.triangle_count(),
        rays / nearest_s / 1e6,
        hits as f64 / rays,
        rays / any_s / 1e6,
        occluded as f64 / rays,
    );
    Ok(())
}
