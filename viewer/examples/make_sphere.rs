//! Writes `data/sphere.obj`: the sample scene's obstacle, an icosphere of radius 0.5 at
//! the origin (where the synthetic wake's sphere is), with radial normals.
//!
//! `cargo run -p qbricks-viewer --example make_sphere [-- OUT.obj [SUBDIVISIONS]]`

use std::path::PathBuf;

use glam::DVec3;
use qbricks_viewer::mesh::icosphere;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/sphere.obj"));
    let subdivisions: u32 = match args.next() {
        Some(s) => s
            .parse()
            .map_err(|e| anyhow::anyhow!("subdivisions `{s}`: {e}"))?,
        None => 4,
    };
    anyhow::ensure!(
        subdivisions <= 6,
        "subdivisions: expected 0..=6, found {subdivisions}"
    );
    let sphere = icosphere(DVec3::ZERO, 0.5, subdivisions);
    let text = sphere.to_obj(&format!(
        "qbricks sample obstacle: icosphere, radius 0.5, centre (0,0,0), {subdivisions} subdivisions\n\
         {} vertices, {} triangles; written by viewer/examples/make_sphere.rs",
        sphere.positions.len(),
        sphere.triangles.len()
    ));
    files::output::write_atomic(&out, |f| {
        use std::io::Write;
        f.write_all(text.as_bytes())
    })
    .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
    println!("{}: {} bytes", out.display(), text.len());
    Ok(())
}
