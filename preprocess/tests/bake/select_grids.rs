//! Which grids `qbricks-bake bake` takes from a file (`bake::select_grids`): every rule of
//! the default choice and of `--grid`, with the indices (file order) it returns or the
//! error it gives.

use qbricks_preprocess::bake::{select_grids, BakeError, GridKind};
use GridKind::{Other, Scalar, Vector};

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

#[test]
fn default_takes_every_vector_grid_in_file_order() {
    let grids = [
        ("density", Scalar),
        ("vel_l0", Vector),
        ("mask", Other),
        ("vel_l1", Vector),
        ("vel_l0", Vector),
    ];
    assert_eq!(select_grids(&grids, &[]).expect("vectors"), vec![1, 3, 4]);
}

#[test]
fn default_without_vectors_takes_the_one_scalar_name() {
    // Several grids of one scalar name (levels) are one field.
    let grids = [("q", Scalar), ("mask", Other), ("q", Scalar)];
    assert_eq!(select_grids(&grids, &[]).expect("scalar"), vec![0, 2]);
    // Two scalar names: ambiguous, named in the message.
    let grids = [("q", Scalar), ("speed", Scalar)];
    match select_grids(&grids, &[]) {
        Err(e @ BakeError::AmbiguousScalar { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains("\"q\"") && msg.contains("\"speed\""), "{msg}");
        }
        other => panic!("expected AmbiguousScalar, got {other:?}"),
    }
    // Nothing bakeable at all.
    assert!(matches!(
        select_grids(&[("mask", Other)], &[]),
        Err(BakeError::NoGrids)
    ));
    assert!(matches!(select_grids(&[], &[]), Err(BakeError::NoGrids)));
}

#[test]
fn named_grids_are_taken_with_every_grid_of_that_name() {
    let grids = [("a", Vector), ("b", Vector), ("a", Vector), ("s", Scalar)];
    assert_eq!(select_grids(&grids, &names(&["a"])).expect("a"), vec![0, 2]);
    // File order, whatever the order of the flags.
    assert_eq!(
        select_grids(&grids, &names(&["b", "a"])).expect("b, a"),
        vec![0, 1, 2]
    );
    // A scalar grid may be chosen by name even when vector grids exist.
    assert_eq!(select_grids(&grids, &names(&["s"])).expect("s"), vec![3]);
}

#[test]
fn named_selection_errors_name_the_grids() {
    let grids = [
        ("vel", Vector),
        ("q", Scalar),
        ("speed", Scalar),
        ("m", Other),
    ];
    match select_grids(&grids, &names(&["nope"])) {
        Err(BakeError::GridNotFound { name, available }) => {
            assert_eq!(name, "nope");
            assert_eq!(available, "\"vel\", \"q\", \"speed\", \"m\"");
        }
        other => panic!("expected GridNotFound, got {other:?}"),
    }
    assert!(matches!(
        select_grids(&grids, &names(&["m"])),
        Err(BakeError::UnsupportedGrid { grid }) if grid == "m"
    ));
    assert!(matches!(
        select_grids(&grids, &names(&["vel", "q"])),
        Err(BakeError::MixedKinds { vector, scalar }) if vector == "\"vel\"" && scalar == "\"q\""
    ));
    assert!(matches!(
        select_grids(&grids, &names(&["q", "speed"])),
        Err(BakeError::SeveralScalarGrids { names }) if names == "\"q\", \"speed\""
    ));
}
