//! The bundled `data/wake_small.qbk` is exactly what baking the bundled
//! `data/wake_small.vdb` gives today, so the README's main command and the viewer's default
//! file can never drift apart from the code.

use crate::common::{qbricks_bake, root};

#[test]
fn bundled_qbk_matches_what_bake_writes_today() {
    let dir = tempfile::tempdir().expect("tempdir");
    let vdb = dir.path().join("wake_small.vdb");
    std::fs::copy(root().join("data/wake_small.vdb"), &vdb).expect("copy sample");
    let out = dir.path().join("wake_small.qbk");
    let run = qbricks_bake()
        .arg("bake")
        .arg(&vdb)
        .arg("--quiet")
        .output()
        .expect("run qbricks-bake");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let want = std::fs::read(root().join("data/wake_small.qbk")).expect("bundled .qbk");
    let got = std::fs::read(&out).expect("baked .qbk");
    assert!(
        want == got,
        "data/wake_small.qbk ({} bytes) differs from what `qbricks-bake bake data/wake_small.vdb` \
         writes now ({} bytes); regenerate it with that command",
        want.len(),
        got.len()
    );
}
