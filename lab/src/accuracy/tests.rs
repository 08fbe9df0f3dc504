//! Statistics, orders and the memory estimate of the accuracy measurement.
use super::*;

#[test]
fn lamb_oseen_stored_q_converges_at_second_order() {
    let opts = AccuracyOptions {
        scene: "lamb-oseen".into(),
        n0: vec![16, 32],
        points: 500,
        ..AccuracyOptions::default()
    };
    let r = accuracy(&opts, &mut |_| {}).expect("accuracy");
    assert_eq!(r.resolutions.len(), 2);
    assert_eq!(r.orders.len(), 1);
    let o = &r.orders[0];
    // Central differences: Q's error falls ≈ 4× per halving of the cell width.
    assert!(o.stored_q_rms > 1.5, "order {}", o.stored_q_rms);
    for res in &r.resolutions {
        assert_eq!(res.boundary_q.points, 0, "one grid has no level boundary");
        assert!(res.reconstructed_q.points > 0);
        assert!(res.stored_q.rms_rel > 0.0 && res.stored_q.rms_rel < 0.5);
    }
    // Vorticity and λ2 come from the same gradient: the same order (λ2 = −Q in this plane
    // flow, so its errors are Q's up to the discrete divergence).
    for (name, v) in [
        ("vorticity", o.stored_vorticity_rms),
        ("lambda2", o.stored_lambda2_rms),
        ("reconstructed vorticity", o.reconstructed_vorticity_rms),
        ("reconstructed lambda2", o.reconstructed_lambda2_rms),
    ] {
        let v = v.expect("measured at both resolutions");
        assert!(v > 1.5 && v > o.stored_q_rms - 0.3, "{name} order {v}");
    }
    let res = &r.resolutions[1];
    assert!((res.lambda2_scale - res.q_scale).abs() < 0.05 * res.q_scale);
    assert!(res.vorticity_scale > 1.0 && res.vorticity_scale < 1.4);
}

#[test]
fn nested_scene_reports_every_measure_across_the_level_boundary() {
    let opts = AccuracyOptions {
        scene: "burgers-nested".into(),
        n0: vec![16, 32],
        levels: 2,
        points: 400,
        rays: 16,
        ..AccuracyOptions::default()
    };
    let r = accuracy(&opts, &mut |_| {}).expect("accuracy");
    for res in &r.resolutions {
        assert_eq!(res.levels.len(), 2);
        for s in [
            &res.boundary_q,
            &res.boundary_vorticity,
            &res.boundary_lambda2,
        ] {
            assert_eq!(s.points, 400);
            assert!(s.rms_rel > 0.0 && s.rms_rel < 0.2, "{s:?}");
        }
        for l in &res.levels {
            assert!(l.vorticity.points > 0 && l.lambda2.points == l.q.points);
        }
    }
    let o = &r.orders[0];
    for (name, v) in [
        ("q", o.boundary_q_rms),
        ("vorticity", o.boundary_vorticity_rms),
        ("lambda2", o.boundary_lambda2_rms),
    ] {
        let v = v.expect("points near the boundary at both resolutions");
        assert!(v > 1.5, "{name} order near the level boundary {v}");
    }
    for v in [o.stored_lambda2_rms, o.stored_vorticity_rms] {
        assert!(v.expect("measured") > o.stored_q_rms - 0.3);
    }
}

#[test]
fn fields_choose_what_is_baked_and_q_is_always_measured() {
    let opts = AccuracyOptions {
        scene: "abc".into(),
        n0: vec![8, 16],
        points: 50,
        rays: 8,
        fields: vec!["q".into(), "lambda2".into()],
        ..AccuracyOptions::default()
    };
    let r = accuracy(&opts, &mut |_| {}).expect("accuracy");
    for res in &r.resolutions {
        assert!(res.stored_q.points > 0 && res.stored_lambda2.points > 0);
        assert_eq!(res.stored_speed.points, 0);
        assert_eq!(res.stored_vorticity.points, 0);
        assert_eq!(res.reconstructed_vorticity.points, 0);
        assert!(res.reconstructed_lambda2.points > 0);
    }
    let o = &r.orders[0];
    assert!(o.stored_lambda2_rms.is_some() && o.reconstructed_lambda2_rms.is_some());
    assert!(o.stored_speed_rms.is_none() && o.stored_vorticity_rms.is_none());
    // Fewer fields, less memory.
    let need = |n| memory_needed("abc", 256, 1, n).expect("layout");
    assert!(need(2) < need(4));
    for (fields, what) in [
        (vec!["speed"], "q is missing"),
        (vec!["q", "helicity"], "unknown field \"helicity\""),
        (vec!["q", "q"], "\"q\" is given twice"),
    ] {
        let opts = AccuracyOptions {
            fields: fields.into_iter().map(String::from).collect(),
            ..opts.clone()
        };
        let e = accuracy(&opts, &mut |_| {}).expect_err("refused");
        assert!(e.to_string().contains(what), "{e}");
    }
}

#[test]
fn exact_hits_approach_the_exact_iso_surface_as_cells_shrink() {
    // The Lamb–Oseen iso-surface is a cylinder around the axis; the viewer's `exact`
    // roots of the reconstructed Q must close in on it at second order (the stored Q
    // and its trilinear reconstruction both are), and the shading normals on its
    // exact normal.
    let opts = AccuracyOptions {
        scene: "lamb-oseen".into(),
        n0: vec![16, 32, 64],
        points: 100,
        rays: 64,
        ..AccuracyOptions::default()
    };
    let r = accuracy(&opts, &mut |_| {}).expect("accuracy");
    for res in &r.resolutions {
        let s = &res.surface;
        assert_eq!(s.rays, 64 * 64);
        assert!(s.hits > 150, "n0 {}: only {} hits", res.n0, s.hits);
        // A hit off by a cell would be a wrong root, not an approximation error.
        assert!(s.position.max_rel < 0.25, "n0 {}: {:?}", res.n0, s.position);
    }
    for w in r.resolutions.windows(2) {
        let (a, b) = (&w[0].surface, &w[1].surface);
        assert!(
            b.position.rms < 0.5 * a.position.rms,
            "position n0 {} → {}: {:.3e} → {:.3e}",
            w[0].n0,
            w[1].n0,
            a.position.rms,
            b.position.rms
        );
        assert!(
            b.normal_deg.rms < 0.6 * a.normal_deg.rms,
            "normal n0 {} → {}: {:.3}° → {:.3}°",
            w[0].n0,
            w[1].n0,
            a.normal_deg.rms,
            b.normal_deg.rms
        );
    }
    for o in &r.orders {
        let p = o.surface_position_rms.expect("hits at both resolutions");
        assert!(p > 1.4, "surface position order {p:.2}");
    }
}

#[test]
fn unknown_scene_is_refused() {
    let opts = AccuracyOptions {
        scene: "nope".into(),
        ..AccuracyOptions::default()
    };
    assert!(matches!(
        accuracy(&opts, &mut |_| {}),
        Err(AccuracyError::UnknownScene(_))
    ));
}
