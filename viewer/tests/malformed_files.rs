//! Files that pass `format::BrickFileView` validation must be safe to render: the viewer's
//! hot loops index the archive with `[]`, trusting validation for every index. Each case
//! here is a crash the `qbk_open` fuzz target found (`fuzz/fuzz_targets/qbk_open.rs`),
//! rebuilt in code from a small test volume so that it needs no stored fixture: it must
//! now be refused with an error naming the file, or, if it opens, walk without a panic.

use std::path::Path;

use format::validate::ValidationError;
use format::{BrickFile, BrickFileView, FormatErrorKind};
use qbricks_viewer::sampling::{Strategy, Tracer};
use qbricks_viewer::testvol::{self, GridSpec};
use qbricks_viewer::transfer::Mode;
use qbricks_viewer::volume::Volume;

/// Two nested grids with a smooth field, a few bricks each.
fn small_volume() -> BrickFile {
    let coarse = GridSpec::covering([0.0; 3], [8.0; 3], 1.0);
    let fine = GridSpec::covering([2.0; 3], [6.0; 3], 0.5);
    let f = |p: [f64; 3]| p[0] + 0.5 * p[1] - 0.25 * p[2];
    testvol::build(&[coarse, fine], &[("q", &f)], 4)
}

/// What the viewer does with an open file, in small: every region, its bricks, the
/// reconstruction at its centre, and a few rays per strategy (as the fuzz target does).
fn walk(view: &BrickFileView) {
    walk_volume(&Volume::new(view).expect("volume"), view);
}

/// [`walk`] of the volume `vol` of `view`.
fn walk_volume(vol: &Volume, view: &BrickFileView) {
    let file = view.file();
    for r in 0..vol.region_count() {
        let reg = vol.region(r);
        let _ = vol.region_brick_ids(r);
        let c: [f64; 3] = std::array::from_fn(|a| 0.5 * (reg.min[a] + reg.max[a]));
        let _ = format::query::region_at(file, vol.to_world(c));
        for f in 0..vol.fields.len() {
            let _ = vol.eval(r, c, f, Some(0));
            let _ = vol.eval_value(r, c, f);
            let _ = vol.shading_gradient(c, f);
            let _ = vol.sample(vol.to_world(c), f);
        }
    }
    let (lo, hi) = (vol.bounds_min, vol.bounds_max);
    let o = lo.map(|x| x - 1.0);
    let d = {
        let d: [f64; 3] = std::array::from_fn(|a| hi[a] + 1.0 - o[a]);
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|x| x / n)
    };
    for (mode, strategy) in [
        (Mode::Iso, Strategy::Exact),
        (Mode::Iso, Strategy::Uniform),
        (Mode::Dvr, Strategy::Bisect),
    ] {
        let mut params = testvol::params(vol, strategy, 0.5, mode, 4.0);
        params.tf.band.sigma = 0.5;
        let accel = qbricks_viewer::accel::Accel::new(params.accel_key());
        let mut tr = Tracer::new(vol, &accel, params);
        match mode {
            Mode::Iso => {
                let _ = tr.iso(o, d, 0.0, f64::INFINITY, 0.37);
            }
            Mode::Dvr => {
                let _ = tr.dvr(o, d, 0.0, f64::INFINITY, 0.37, &mut |_, _| [1.0; 3]);
            }
        }
    }
}

fn open(file: &BrickFile, name: &str) -> Result<BrickFileView, format::FormatError> {
    let bytes = format::writer::to_bytes(file).expect("to_bytes");
    BrickFileView::from_bytes(Path::new(name), &bytes)
}

#[test]
fn intact_volume_walks() {
    let view = open(&small_volume(), "intact.qbk").expect("open");
    walk(&view);
}

/// Fuzz crash 1: brick dims whose product overflows u64. Validation multiplied them
/// unchecked, so 2^22 x 2^21 x 2^21 wrapped to 0 cells in release builds, the brick passed
/// the range check against the value arrays, and `Volume::eval` indexed far past them.
#[test]
fn brick_dims_overflowing_the_cell_count_are_refused() {
    let base = small_volume();
    // A brick some region reads, so that the reconstruction would reach it.
    let b = base.region_bricks[0] as usize;
    for dims in [
        [1 << 22, 1 << 21, 1 << 21],
        [u32::MAX; 3],
        [1 << 31, 1 << 31, 4],
    ] {
        let mut file = base.clone();
        file.bricks[b].dims = dims;
        match open(&file, "overflow.qbk") {
            Err(e) => {
                let msg = e.to_string();
                assert!(
                    matches!(
                        e.kind,
                        FormatErrorKind::Invalid(ValidationError::BrickTooManyCells { brick, .. })
                            if brick == b
                    ) && msg.contains("overflow.qbk")
                        && msg.contains(&format!("bricks[{b}]")),
                    "{dims:?}: {msg}"
                );
            }
            Ok(view) => panic!("{dims:?}: opened ({view:?})"),
        }
    }
}

/// Fuzz crash 1 again, for a file opened as renders open it (its bricks checked where they
/// are read): the open succeeds, and the file's summary (`info`, Python's `info_json`)
/// counts the brick's cells as `u64::MAX` instead of overflowing (a panic in a build with
/// overflow checks, a wrapped count of 0 without).
#[test]
fn brick_dims_overflowing_the_cell_count_are_summarised_saturated() {
    let mut file = small_volume();
    let b = file.region_bricks[0] as usize;
    file.bricks[b].dims = [1 << 22, 1 << 21, 1 << 21];
    let view = open_on_use(&file, "overflow.qbk").expect("opens: checked where read");
    let info = qbricks_viewer::info::info(&view);
    assert_eq!(info.cells, u64::MAX);
    let vol = Volume::new(&view).expect("volume");
    walk_volume(&vol, &view);
    assert!(matches!(
        vol.structure_error(),
        Some(ValidationError::BrickTooManyCells { brick, .. }) if *brick == b
    ));
}

/// Fuzz timeout 1: a level's cell width of 1.1e-12 under bricks of width 1 (the fuzzer
/// changed one byte of a baked file). The viewer steps in units of the region's finest
/// level width, so one `uniform` ray took a million samples per region and a frame
/// hours. Now refused: brick widths must be their level's, and a region's finest level
/// the finest of its bricks.
#[test]
fn level_width_far_from_its_bricks_is_refused() {
    let base = small_volume();
    let b = base.region_bricks[0] as usize;
    let level = base.bricks[b].level as usize;
    let mut file = base.clone();
    file.levels[level].cell_width = 1.1368683772161603e-12;
    let err = open(&file, "tiny_level.qbk")
        .expect_err("a level width far from its bricks' must not open");
    let msg = err.to_string();
    assert!(
        matches!(
            err.kind,
            FormatErrorKind::Invalid(ValidationError::BrickWidthNotLevels { .. })
        ) && msg.contains("tiny_level.qbk")
            && msg.contains("cell_width"),
        "{msg}"
    );

    // The same slowness was possible through a stored `finest_level` naming an extra,
    // very fine level without bricks. Format 3 stores none: a region's step width is its
    // bricks' finest level's, whatever other levels the file lists.
    let mut file = base.clone();
    file.levels.push(format::Level {
        cell_width: 1.1368683772161603e-12,
        cells: 0,
        bricks: 0,
    });
    let view = open(&file, "finest.qbk").expect("an unused level is harmless");
    let vol = Volume::new(&view).expect("volume");
    let reg = base.regions[0];
    let finest = base.region_bricks
        [reg.bricks_start as usize..(reg.bricks_start + reg.bricks_len) as usize]
        .iter()
        .map(|&b| base.bricks[b as usize].cell_width)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(vol.step_width(0), finest);
    assert_eq!(vol.region(0).finest_w, finest);
}

/// Fuzz timeout 2 (format 3): a KD split moved far outside the data gave a region a box
/// reaching 1e30 units past it, and `exact` stepped through that box cell by cell for
/// minutes. A split outside the bounds is now refused; a split inside the bounds but
/// outside its own node's cell still opens, and every region's box stays inside the
/// data (the cells are clamped), so every walk stays short.
#[test]
fn a_split_outside_its_cell_gives_no_box_past_the_data() {
    let base = small_volume();
    assert!(base.kd_nodes.len() > 2);
    let mut far = base.clone();
    let last = far.kd_nodes.len() - 1;
    far.kd_nodes[last].split = 1e30;
    let err = open(&far, "far_split.qbk").expect_err("a split outside the bounds");
    assert!(
        matches!(
            err.kind,
            FormatErrorKind::Invalid(ValidationError::KdSplitOutsideBounds { .. })
        ) && err.to_string().contains("far_split.qbk"),
        "{err}"
    );
    // Inside the bounds, outside the cell: every deeper node's split moved to a corner of
    // the data, on its axis.
    for corner in [0, 1] {
        let mut odd = base.clone();
        for (n, node) in odd.kd_nodes.iter_mut().enumerate().skip(1) {
            let a = usize::from(base.kd_axes[n]);
            node.split = if corner == 0 {
                base.bounds.min[a]
            } else {
                base.bounds.max[a]
            };
        }
        let view = open(&odd, "odd_split.qbk").expect("splits inside the bounds open");
        let vol = Volume::new(&view).expect("volume");
        for r in 0..vol.region_count() {
            let reg = vol.region(r);
            for a in 0..3 {
                assert!(
                    reg.min[a] >= vol.bounds_min[a] && reg.max[a] <= vol.bounds_max[a],
                    "region {r} reaches past the data: {reg:?}"
                );
            }
            // Clamped cells still partition the data: no two boxes share interior (an
            // unclamped cell of a split outside its node reaches into its neighbours).
            for q in r + 1..vol.region_count() {
                let other = vol.region(q);
                let overlap =
                    (0..3).all(|a| reg.min[a] < other.max[a] && other.min[a] < reg.max[a]);
                assert!(!overlap, "regions {r} and {q} overlap: {reg:?} {other:?}");
            }
        }
        walk(&view);
    }
}

/// Fuzz crash (2026-11-26): a brick moved about 1e20 cells away from the data. The file
/// validates (a brick may lie anywhere), and the dual-cell mask of a region reading only
/// that brick took its cell indices from the brick's far lattice: `i64` arithmetic on
/// them overflowed (a panic with overflow checks, a garbage mask without). Such a region
/// gets no mask now, so every strategy walks it (run with overflow checks by `.ci/run`).
#[test]
fn a_brick_far_from_the_data_walks() {
    let base = small_volume();
    let mut opened = 0;
    for b in 0..base.bricks.len() {
        for far in [1e20, -1e20, 3e15] {
            let mut file = base.clone();
            for a in 0..3 {
                file.bricks[b].origin[a] += far;
            }
            if let Ok(view) = open(&file, "far.qbk") {
                walk(&view);
                opened += 1;
            }
        }
    }
    assert!(opened > 0, "no file with a far brick opened");
}

/// Opens `file` as every render does ([`qbricks_viewer::dataset::render_options`]): only
/// what does not grow with the data is checked at open, the rest where it is read.
fn open_on_use(file: &BrickFile, name: &str) -> Result<BrickFileView, format::FormatError> {
    let bytes = format::writer::to_bytes(file).expect("to_bytes");
    BrickFileView::from_bytes_with(
        Path::new(name),
        &bytes,
        &qbricks_viewer::dataset::render_options(true),
    )
}

/// A frame of `vol` in `mode` with the `exact` or `bisect` default strategy, 24² pixels,
/// the default camera.
fn frame(vol: &Volume, mode: Mode) -> qbricks_viewer::render::Frame {
    let mut state = qbricks_viewer::view_state::ViewState::default_for_volume(vol);
    state.width = 24;
    state.height = 24;
    state.mode = mode;
    state.strategy = match mode {
        Mode::Iso => Strategy::Exact,
        Mode::Dvr => Strategy::Bisect,
    };
    let meshes = qbricks_viewer::mesh::Meshes::empty();
    let scene = qbricks_viewer::scene::Scene::new(vol, &state, &meshes).expect("scene");
    qbricks_viewer::render::render(&scene)
}

/// Damages of a file's bricks, regions and KD-tree that a faulty writer could leave, one
/// each, on a part that frames read.
fn damaged_files() -> Vec<(&'static str, BrickFile)> {
    let base = small_volume();
    let b = base.region_bricks[0] as usize;
    let mut out = Vec::new();
    let mut f = base.clone();
    f.bricks[b].first_value = f.fields[0].values.len() as u64;
    out.push(("a brick's values past the arrays", f));
    let mut f = base.clone();
    f.bricks[b].level = 7;
    out.push(("a brick's level that does not exist", f));
    let mut f = base.clone();
    f.bricks[b].cell_width *= 3.0;
    f.bricks[b].inv_cell_width = 1.0 / f.bricks[b].cell_width;
    out.push(("a brick's width not its level's", f));
    let mut f = base.clone();
    let last = f.region_bricks.len() - 1;
    f.region_bricks[last] = f.bricks.len() as u32 + 5;
    out.push(("a region's entry naming no brick", f));
    let mut f = base.clone();
    f.regions[1].bricks_len = f.region_bricks.len() as u32 + 1;
    out.push(("a region's list past the entries", f));
    let mut f = base.clone();
    f.kd_nodes[0].right = f.kd_nodes.len() as u32 + 3;
    out.push(("a KD child that does not exist", f));
    let mut f = base.clone();
    f.kd_nodes[0].split = f64::NAN;
    out.push(("a KD split that is NaN", f));
    let mut f = base;
    f.kd_axes[0] = 5;
    out.push(("a KD axis past z", f));
    out
}

/// A file opened as renders open it costs nothing that grows with the data to open, so a
/// damaged brick, region or tree opens; the frames that read the damage read that part as
/// empty, never panic, and leave the very error an open that checks everything gives,
/// for the command to report (`Volume::check_structure`, naming the file).
#[test]
fn damage_opened_to_be_checked_on_use_is_found_where_frames_read_it() {
    for (what, file) in damaged_files() {
        let Err(whole) = open(&file, "damaged.qbk") else {
            panic!("{what}: the whole check passed");
        };
        let FormatErrorKind::Invalid(want) = &whole.kind else {
            panic!("{what}: {whole}");
        };
        let view = open_on_use(&file, "damaged.qbk")
            .unwrap_or_else(|e| panic!("{what}: refused at open: {e}"));
        let vol = Volume::new(&view).expect("volume");
        assert!(
            vol.structure_error().is_none(),
            "{what}: found before any read"
        );
        // Frames first, then everything a walk reads.
        for mode in [Mode::Iso, Mode::Dvr] {
            let _ = frame(&vol, mode);
        }
        walk_volume(&vol, &view);
        let got = vol
            .structure_error()
            .unwrap_or_else(|| panic!("{what}: not found"));
        assert_eq!(got, want, "{what}");
        let msg = vol
            .check_structure(Path::new("damaged.qbk"))
            .expect_err("reported")
            .to_string();
        assert_eq!(msg, whole.to_string(), "{what}");
    }
}

/// Checked where it is read or all at open, an intact file renders the same frames, bit
/// for bit, and reports nothing.
#[test]
fn an_intact_file_renders_the_same_checked_on_use() {
    let file = small_volume();
    let whole = open(&file, "intact.qbk").expect("open");
    let on_use = open_on_use(&file, "intact.qbk").expect("open on use");
    assert_eq!(on_use.structure(), format::Structure::OnUse);
    let (a, b) = (
        Volume::new(&whole).expect("volume"),
        Volume::new(&on_use).expect("volume"),
    );
    assert_eq!(a.finest_w.to_bits(), b.finest_w.to_bits());
    for mode in [Mode::Iso, Mode::Dvr] {
        let (fa, fb) = (frame(&a, mode), frame(&b, mode));
        assert!(fa.hits > 0, "{mode:?}: nothing seen");
        assert!(fa == fb, "{mode:?}");
    }
    walk(&on_use);
    assert!(b.structure_error().is_none());
}
