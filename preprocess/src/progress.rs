//! How far a bake has come, from the stage it is in: what the progress bar and its time
//! left are drawn from. A bake reports its stages by name (`stage` callbacks of
//! [`crate::bake::bake_with_progress`] and [`crate::request`]); each stage takes a share of
//! the bake's time that depends little on the input's size, so the share of the stages done
//! says how far it is, and the time taken so far over that share what is left.
//!
//! The shares are the means of two bakes each of three inputs on the build machine
//! (`--progress`): a one-grid 16.8 M-cell ABC flow, the three-level n0-128 wake and the
//! independent three-level layout; a stage's share varied by up to 0.2 between them, so the
//! time left is an estimate, said as "about". Reading the VDB finds the leaves; they are
//! decoded while the cells are made.

/// Every stage a bake reports, in order, with its share of a bake's time.
pub const STAGES: [(&str, f64); 9] = [
    ("reading VDB", 0.01),
    ("selecting grids", 0.0),
    ("reading cells", 0.25),
    ("classifying leaf cells", 0.03),
    ("bricking", 0.03),
    ("deriving fields", 0.22),
    ("building regions", 0.29),
    ("assembling", 0.07),
    ("writing", 0.10),
];

/// The share of a bake done when `stage` starts (0 for the first, just under 1 for the
/// last); `None` for a name that is not a stage of [`STAGES`].
pub fn done_at(stage: &str) -> Option<f64> {
    let at = STAGES.iter().position(|(name, _)| *name == stage)?;
    Some(STAGES[..at].iter().map(|(_, share)| share).sum())
}

/// Seconds a bake has left, `elapsed` seconds after `stage` started: estimated from the
/// share done (`None` until some is, or for an unknown stage).
pub fn seconds_left(stage: &str, elapsed: f64) -> Option<f64> {
    let done = done_at(stage)?;
    (done > 0.0).then(|| elapsed * (1.0 - done) / done)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_add_up_and_every_stage_is_known() {
        let total: f64 = STAGES.iter().map(|(_, s)| s).sum();
        assert!((total - 1.0).abs() < 1e-9, "{total}");
        assert_eq!(done_at("reading VDB"), Some(0.0));
        assert_eq!(seconds_left("reading VDB", 3.0), None);
        let left = seconds_left("deriving fields", 3.2).expect("some done");
        assert!((left - 6.8).abs() < 1e-9, "{left}"); // 0.32 done
        assert_eq!(done_at("no such stage"), None);
    }
}

#[cfg(test)]
mod bake_tests {
    use std::sync::atomic::AtomicBool;
    use std::sync::Mutex;

    use super::STAGES;
    use crate::grid::{AnyGrid, Grid, Leaf, Transform, LEAF_VOXELS};
    use crate::request::{bake_file, BakeRequest};
    use crate::vdb::write::{write_vdb, Compression};

    /// A bake reports exactly the stages the table knows, in its order: a stage renamed,
    /// added or moved in the pipeline fails here instead of stalling the bar.
    #[test]
    fn a_bake_reports_every_stage_of_the_table_in_order() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (input, output) = (dir.path().join("in.vdb"), dir.path().join("out.qbk"));
        let leaf = |origin| Leaf {
            origin,
            active: [u64::MAX; 8],
            values: Box::new(std::array::from_fn::<_, LEAF_VOXELS, _>(|n| {
                [n as f32 * 1e-3, (n % 7) as f32, 1.0]
            })),
        };
        let grid = Grid {
            name: "vel".into(),
            transform: Transform {
                voxel_size: [0.1; 3],
                translation: [0.05; 3],
            },
            background: [0.0; 3],
            leaves: vec![leaf([0, 0, 0]), leaf([8, 0, 0])],
            tiles: Vec::new(),
        };
        write_vdb(&input, &[AnyGrid::Vec3s(grid)], Compression::Zip).expect("write");
        let heard = Mutex::new(Vec::new());
        let plan = BakeRequest::default().plan().expect("plan");
        let stage = |name: &str| heard.lock().expect("lock").push(name.to_string());
        bake_file(&input, &output, &plan, &stage, &AtomicBool::new(false)).expect("bake");
        let names: Vec<&str> = STAGES.iter().map(|(n, _)| *n).collect();
        assert_eq!(heard.into_inner().expect("lock"), names);
    }
}
