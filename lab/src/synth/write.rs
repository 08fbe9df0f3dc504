//! A sampled scene written as a VDB file, with its metadata and a per-grid summary.

use super::*;

/// What `qbricks-lab synth` writes.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    pub scene: String,
    pub n0: u32,
    pub levels: u32,
    pub compression: Compression,
    /// Also write the speed `|u|` of each velocity grid as a float grid named
    /// `speed` / `speed_l<k>` with the same active voxels (a scalar-grid test input).
    pub speed_grids: bool,
    /// Write the velocity grids as MAC grids (class `staggered`, see
    /// [`sample_grid_with`]); speed grids stay cell-centred.
    pub staggered: bool,
    /// Frame (1-based) of a time-dependent scene (`ring-plume`); ignored by the others.
    pub frame: u64,
    /// Sample the scene on these nested boxes instead of the layout `n0` and `levels` make
    /// (which are then ignored).
    pub boxes: Option<BoxLayout>,
}

impl SynthOptions {
    /// The grids to sample, finest first, and what a memory error calls the request.
    fn layouts(&self) -> Result<(Vec<GridLayout>, Request), SynthError> {
        match &self.boxes {
            None => Ok((
                scene_layout(&self.scene, self.n0, self.levels)?,
                Request::n0(&self.scene, self.n0),
            )),
            Some(b) => {
                if analytic::scene(&self.scene).is_none() {
                    return Err(SynthError::UnknownScene {
                        name: self.scene.clone(),
                    });
                }
                let grids = b.grids(&self.scene)?;
                let request = Request::boxes(&self.scene, grids.len());
                Ok((grids, request))
            }
        }
    }
}

/// One written grid, for the command's summary.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSummary {
    pub name: String,
    pub value_type: &'static str,
    pub voxel_size: f64,
    pub active_voxels: u64,
    pub leaves: usize,
}

/// Samples a scene and writes it as a VDB file. Returns per-grid counts and the file size.
///
/// Grid metadata besides what the writer always adds: `scene` (string), `level` (int32,
/// 0 = finest), `origin` (vec3d, world-space minimum corner of the grid's box) and
/// `dx` (double, voxel size). File metadata: `scene`, `levels`, and `n0` or, on the boxes
/// of a layout, `boxes` (the layout as compact JSON).
pub fn write_scene(
    path: &std::path::Path,
    opts: &SynthOptions,
) -> Result<(Vec<GridSummary>, u64), SynthError> {
    let (layouts, request) = opts.layouts()?;
    check_write_memory(&request, &layouts, opts.speed_grids)?;
    let velocity = sample_scene(&opts.scene, &layouts, opts.staggered, opts.frame)?;
    let mut grids: Vec<AnyGrid> = Vec::new();
    let mut metadata: Vec<MetaMap> = Vec::new();
    let mut summary = Vec::new();
    let meta_for = |layout: &GridLayout, level: usize| {
        let mut m = MetaMap::new();
        m.insert("scene".into(), MetaValue::String(opts.scene.clone()));
        m.insert("level".into(), MetaValue::Int32(level as i32));
        m.insert(
            "origin".into(),
            MetaValue::Vec3d(layout.lo.map(|v| v as f64 * layout.voxel_size)),
        );
        m.insert("dx".into(), MetaValue::Double(layout.voxel_size));
        m
    };
    for (level, (grid, layout)) in velocity.iter().zip(&layouts).enumerate() {
        summary.push(GridSummary {
            name: grid.name.clone(),
            value_type: "vec3s",
            voxel_size: layout.voxel_size,
            active_voxels: grid.active_voxel_count(),
            leaves: grid.leaves.len(),
        });
        let mut m = meta_for(layout, level);
        if opts.staggered {
            m.insert("class".into(), MetaValue::String("staggered".into()));
        }
        metadata.push(m);
    }
    let speed: Vec<Grid<f32>> = if opts.speed_grids && opts.staggered {
        let mut centred = sample_scene(&opts.scene, &layouts, false, opts.frame)?;
        for (c, v) in centred.iter_mut().zip(&velocity) {
            c.name.clone_from(&v.name);
        }
        centred.iter().map(speed_grid).collect()
    } else if opts.speed_grids {
        velocity.iter().map(speed_grid).collect()
    } else {
        Vec::new()
    };
    grids.extend(velocity.into_iter().map(AnyGrid::Vec3s));
    for (level, (grid, layout)) in speed.into_iter().zip(&layouts).enumerate() {
        summary.push(GridSummary {
            name: grid.name.clone(),
            value_type: "float",
            voxel_size: layout.voxel_size,
            active_voxels: grid.active_voxel_count(),
            leaves: grid.leaves.len(),
        });
        metadata.push(meta_for(layout, level));
        grids.push(AnyGrid::Float(grid));
    }
    if opts.scene == "ring-plume" {
        // The smoke the ring carries, at voxel centres (class "fog volume", as Mantaflow).
        let plume = analytic::RingPlume::frame(opts.frame);
        for (level, layout) in layouts.iter().enumerate() {
            let density = sample_scalar("density", layout, |p| plume.density(p));
            summary.push(GridSummary {
                name: density.name.clone(),
                value_type: "float",
                voxel_size: layout.voxel_size,
                active_voxels: density.active_voxel_count(),
                leaves: density.leaves.len(),
            });
            let mut m = meta_for(layout, level);
            m.insert("class".into(), MetaValue::String("fog volume".into()));
            metadata.push(m);
            grids.push(AnyGrid::Float(density));
        }
    }
    let mut options = WriteOptions::new(opts.compression);
    options.grid_metadata = metadata;
    options
        .file_metadata
        .insert("scene".into(), MetaValue::String(opts.scene.clone()));
    match &opts.boxes {
        None => {
            options
                .file_metadata
                .insert("n0".into(), MetaValue::Int32(opts.n0 as i32));
            options
                .file_metadata
                .insert("levels".into(), MetaValue::Int32(opts.levels as i32));
        }
        Some(b) => {
            options
                .file_metadata
                .insert("boxes".into(), MetaValue::String(b.to_json()));
            options
                .file_metadata
                .insert("levels".into(), MetaValue::Int32(layouts.len() as i32));
        }
    }
    if opts.scene == "ring-plume" {
        options.file_metadata.insert(
            "frame".into(),
            MetaValue::Int64(i64::try_from(opts.frame).unwrap_or(i64::MAX)),
        );
    }
    let bytes = write_vdb_with(path, &grids, &options)?;
    Ok((summary, bytes))
}
