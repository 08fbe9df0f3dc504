//! The iso-surface as the viewer's `exact` strategy finds it in a bake, against the exact
//! flow: where the rays hit, and how far Q and its normal are from the exact ones there.

use super::*;

/// The iso value of the surface checks when none is given (see [`AccuracyOptions::iso`]).
pub(super) fn default_iso(flow: &dyn Flow, opts: &AccuracyOptions) -> Result<f64, AccuracyError> {
    if opts.scene.starts_with("wake") {
        return Ok(0.05);
    }
    // The coarsest grid spans the domain; 33 points per axis find the peak of these
    // smooth flows to well within the fifth taken of it.
    let layout = scene_layout(&opts.scene, 8, 1)?;
    let Some(g) = layout.first() else {
        return Ok(0.05);
    };
    let (lo, hi) = (
        g.lo.map(|i| i as f64 * g.voxel_size),
        g.hi.map(|i| i as f64 * g.voxel_size),
    );
    let n = 32;
    let mut max = 0.0f64;
    for i in 0..=n {
        for j in 0..=n {
            for k in 0..=n {
                let t = [i, j, k].map(|c| f64::from(c) / f64::from(n));
                max = max.max(flow.q(std::array::from_fn(|a| lo[a] + t[a] * (hi[a] - lo[a]))));
            }
        }
    }
    Ok(if max > 0.0 { 0.2 * max } else { 0.05 })
}

/// Central-difference gradient of the exact Q. The flows give the velocity gradient in
/// closed form but not its derivatives; a step of 10⁻⁴ cell leaves a truncation error far
/// below the reconstruction's and a rounding error ≈ 10⁻¹² relative.
pub(super) fn exact_q_gradient(flow: &dyn Flow, p: [f64; 3], width: f64) -> DVec3 {
    let d = 1e-4 * width;
    DVec3::from_array(std::array::from_fn(|a| {
        let (mut hi, mut lo) = (p, p);
        hi[a] += d;
        lo[a] -= d;
        (flow.q(hi) - flow.q(lo)) / (2.0 * d)
    }))
}

/// Casts `opts.rays`² camera rays through `file` with the viewer's `exact` strategy and
/// compares each hit with the exact flow.
pub(super) fn surface_errors(
    flow: &dyn Flow,
    file: &BrickFile,
    opts: &AccuracyOptions,
    iso: f64,
    n0: u32,
) -> Result<SurfaceReport, AccuracyError> {
    let view_err = |e: &dyn std::fmt::Display| AccuracyError::View(n0, e.to_string());
    let path = std::path::Path::new("accuracy.qbk");
    let bytes = format::writer::to_bytes(file).map_err(|e| view_err(&e))?;
    let view = format::BrickFileView::from_bytes(path, &bytes).map_err(|e| view_err(&e))?;
    let vol = Volume::new(&view).map_err(|e| view_err(&e))?;
    let mut st = ViewState::default_for_volume(&vol);
    st.iso_field = "q".into();
    st.set_iso(iso);
    st.mode = Mode::Iso;
    st.strategy = Strategy::Exact;
    st.spp = 1;
    st.width = opts.rays.max(1);
    st.height = opts.rays.max(1);
    let meshes = Meshes::empty();
    let scene = Scene::new(&vol, &st, &meshes).map_err(|e| view_err(&e))?;
    let mut caster = RayCaster::new(&scene);
    let (mut pos, mut ang) = (Acc::default(), Acc::default());
    for y in 0..st.height {
        for x in 0..st.width {
            let (ray, jit) = caster.camera_ray(x, y, 0);
            let Some(hit) = caster.surface(&ray, jit) else {
                continue;
            };
            // The local cell width (of the finest brick at the hit).
            let w = vol
                .region_at(hit.local)
                .map_or(vol.finest_w, |r| vol.step_width(r));
            let p = hit.world.to_array();
            if !flow.is_smooth_near(p, 2.0 * w) {
                continue;
            }
            let g = exact_q_gradient(flow, p, w);
            let gl = g.length();
            if gl.is_nan() || gl <= 0.0 {
                continue;
            }
            pos.add((flow.q(p) - iso).abs() / gl);
            let cos = (hit.normal.dot(g) / gl).abs().min(1.0);
            ang.add(cos.acos().to_degrees());
        }
    }
    Ok(SurfaceReport {
        iso,
        rays: u64::from(st.width) * u64::from(st.height),
        hits: pos.n,
        position: pos.stats(vol.finest_w),
        normal_deg: ang.stats(1.0),
    })
}
