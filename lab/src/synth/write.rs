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
    /// Whether the scene can be written (see [`write_scene`]), without sampling anything:
    /// the errors `write_scene` would give before it starts.
    pub fn check(&self) -> Result<(), SynthError> {
        self.layouts().map(|_| ())
    }

    /// Float grids written per velocity grid: speed, and ring-plume's density.
    fn scalar_grids(&self) -> u64 {
        u64::from(self.speed_grids) + u64::from(self.scene == "ring-plume")
    }

    /// The grids to write, finest first, what an error calls the request, and the file's
    /// bound: checked as [`check_write`] checks them (not against the memory a sampled
    /// scene would take: `synth` does not hold its grids).
    fn layouts(&self) -> Result<(Vec<GridLayout>, Request, u64), SynthError> {
        let (layouts, request) = match &self.boxes {
            None => (
                layout::scene_boxes(&self.scene, self.n0, self.levels)?,
                Request::n0(&self.scene, self.n0),
            ),
            Some(b) => {
                let grids = b.check()?;
                if analytic::scene(&self.scene).is_none() {
                    return Err(SynthError::UnknownScene {
                        name: self.scene.clone(),
                    });
                }
                let request = Request::boxes(&self.scene, grids.len());
                (grids, request)
            }
        };
        let bytes = check_write(&request, &layouts, self.scalar_grids())?;
        Ok((layouts, request, bytes))
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
pub fn write_scene(
    path: &std::path::Path,
    opts: &SynthOptions,
) -> Result<(Vec<GridSummary>, u64), SynthError> {
    write_scene_with(path, opts, &mut |_, _| {})
}

/// [`write_scene`], telling `progress` how far it is.
///
/// The grids are never held: their leaves' shapes are laid out first, and the values are
/// sampled a batch of leaves at a time while the file is written
/// ([`preprocess::vdb::write::write_sources`]), so memory stays near the shapes (about 300
/// bytes a leaf) and one batch whatever the scene's size. `progress` is told the leaves
/// written so far, out of the total it is first given (`progress(0, total)`).
///
/// Grid metadata besides what the writer always adds: `scene` (string), `level` (int32,
/// 0 = finest), `origin` (vec3d, world-space minimum corner of the grid's box) and
/// `dx` (double, voxel size). File metadata: `scene`, `levels`, and `n0` or, on the boxes
/// of a layout, `boxes` (the layout as compact JSON).
pub fn write_scene_with(
    path: &std::path::Path,
    opts: &SynthOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(Vec<GridSummary>, u64), SynthError> {
    let (layouts, request, bound) = opts.layouts()?;
    // Raw values have a known size: refuse at once what the disk cannot take, before
    // anything is sampled. Compressed ones do not (a disk that fills mid-way fails the
    // write, which leaves nothing behind).
    if opts.compression != Compression::Zip {
        files::output::check_space(&request.what, path, bound).map_err(|error| {
            SynthError::Memory {
                error,
                hint: request.hint,
            }
        })?;
    }
    let flow =
        analytic::scene_at(&opts.scene, opts.frame).ok_or_else(|| SynthError::UnknownScene {
            name: opts.scene.clone(),
        })?;
    let flow: &dyn Flow = flow.as_ref();
    let shapes: Vec<Vec<LeafShape>> = layouts.iter().map(leaf_shapes).collect();
    let staggered = opts.staggered;
    let plume = analytic::RingPlume::frame(opts.frame);
    let mut sources: Vec<AnySource<'_>> = Vec::new();
    let mut metadata: Vec<MetaMap> = Vec::new();
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
    for (level, (layout, shapes)) in layouts.iter().zip(&shapes).enumerate() {
        let grid = source(layout, shapes, layout.name.clone(), move |i| {
            velocity_values(flow, layout, &shapes[i], staggered)
        });
        sources.push(AnySource::Vec3s(grid));
        let mut m = meta_for(layout, level);
        if opts.staggered {
            m.insert("class".into(), MetaValue::String("staggered".into()));
        }
        metadata.push(m);
    }
    if opts.speed_grids {
        // From the velocity at the voxel centres, also when the velocity grids are MAC
        // grids.
        for (level, (layout, shapes)) in layouts.iter().zip(&shapes).enumerate() {
            let grid = source(layout, shapes, speed_name(&layout.name), move |i| {
                speeds(&velocity_values(flow, layout, &shapes[i], false))
            });
            sources.push(AnySource::Float(grid));
            metadata.push(meta_for(layout, level));
        }
    }
    if opts.scene == "ring-plume" {
        // The smoke the ring carries, at voxel centres (class "fog volume", as Mantaflow).
        let density = |p: [f64; 3]| plume.density(p);
        for (level, (layout, shapes)) in layouts.iter().zip(&shapes).enumerate() {
            let grid = source(layout, shapes, "density".to_string(), move |i| {
                scalar_values(layout, &shapes[i], &density)
            });
            sources.push(AnySource::Float(grid));
            let mut m = meta_for(layout, level);
            m.insert("class".into(), MetaValue::String("fog volume".into()));
            metadata.push(m);
        }
    }
    let summary: Vec<GridSummary> = sources
        .iter()
        .map(|g| GridSummary {
            name: g.name().to_string(),
            value_type: match g {
                AnySource::Float(_) => "float",
                _ => "vec3s",
            },
            voxel_size: g.transform().voxel_size[0],
            active_voxels: g.active_voxel_count(),
            leaves: g.leaf_count(),
        })
        .collect();
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
    let total: u64 = sources.iter().map(|g| g.leaf_count() as u64).sum();
    progress(0, total);
    let bytes = write_sources(path, &sources, &options, &mut |done| progress(done, total))?;
    Ok((summary, bytes))
}

/// A grid on `layout`'s leaves `shapes` whose leaf `i` holds `values(i)`.
fn source<'a, V: Copy + Default + Send + Sync + 'a>(
    layout: &GridLayout,
    shapes: &[LeafShape],
    name: String,
    values: impl Fn(usize) -> [V; LEAF_VOXELS] + Sync + 'a,
) -> GridSource<'a, V> {
    GridSource {
        name,
        transform: layout.transform(),
        background: V::default(),
        tiles: std::borrow::Cow::Borrowed(&[]),
        leaves: shapes.to_vec(),
        values: Box::new(move |i| std::borrow::Cow::Owned(values(i))),
    }
}
