//! The bundled sample `data/wake_small.vdb` is exactly what the README's synth command
//! writes today, so it cannot go stale. If this fails after an intended change to the
//! analytic flows, the layout or the writer, regenerate the file with that command.

use crate::common::root;
use lab::synth::{write_scene, SynthOptions};
use qbricks_preprocess::vdb::write::Compression;

/// The command in the README's *Bundled data* section, and the options it stands for.
const COMMAND: &str =
    "qbricks-lab synth wake -o data/wake_small.vdb --n0 48 --levels 3 --compression zip";

fn options() -> SynthOptions {
    SynthOptions {
        scene: "wake".into(),
        n0: 48,
        levels: 3,
        compression: Compression::Zip,
        speed_grids: false,
        staggered: false,
        frame: 1,
        boxes: None,
    }
}

#[test]
fn bundled_sample_matches_what_synth_writes_today() {
    let bundled = root().join("data/wake_small.vdb");
    let want = std::fs::read(&bundled).expect("data/wake_small.vdb is bundled");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("wake_small.vdb");
    let (_, size) = write_scene(&path, &options()).expect("write");
    let got = std::fs::read(&path).expect("read");
    assert_eq!(size, got.len() as u64);
    assert!(
        got == want,
        "data/wake_small.vdb ({} bytes) differs from what `{COMMAND}` writes now ({} bytes); \
         regenerate it with that command",
        want.len(),
        got.len()
    );
}

#[test]
fn readme_documents_the_sample_command() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README");
    assert!(
        readme.contains(COMMAND),
        "README.md should give the command that makes data/wake_small.vdb: {COMMAND}"
    );
}
