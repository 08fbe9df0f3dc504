//! A frame over ranks (see the module above): each rank finds the first crossings in its
//! own regions, rank 0 keeps the nearest per ray, the shadow rays go round once, and rank
//! 0 shades and accumulates the pixels exactly as one process does.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::Exchange;
use crate::film;
use crate::integrate::Accum;
use crate::mesh::MeshHit;
use crate::ray::{
    base_colour, first_surface_through, lit, mesh_point, shadow_ray, FirstSurface, RayCaster,
    ShadowRay, VolumeShadow,
};
use crate::render::{Frame, Renderer};
use crate::sampling::{Stats, Strategy};
use crate::scene::Scene;
use crate::transfer::Mode;

/// A view one frame over ranks cannot render: what it has, and what to do instead.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "one frame over {ranks} MPI ranks renders one opaque iso-surface (`exact`, with shadows) \
     or a dvr band (`uniform` or `paper`, without shadows), meshes and clip planes included; \
     this view has {what}: render it without mpirun, or share the frames of a sequence \
     ('frame_####.qbk') over the ranks"
)]
pub struct Unsupported {
    pub ranks: usize,
    pub what: String,
}

/// A rank's message that cannot be read (a rank of another build or run).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("one frame over ranks: the message of rank {rank} {what}")]
pub struct PartError {
    pub rank: usize,
    pub what: String,
}

/// What one rank did for a frame (`render --json`, `ranks`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RankReport {
    pub rank: usize,
    /// The rank's wall time for the frame, ms.
    pub ms: f64,
    /// Of it, the time not spent tracing its own rays: the exchanges, and at rank 0 the
    /// compositing and shading, ms.
    pub composite_ms: f64,
    /// The regions it searches, and the bricks those hold.
    pub regions: u64,
    pub bricks_owned: u64,
    /// The bricks whose values its rays read (the regions it searched or evaluated a hit in).
    pub bricks_touched: u64,
    /// Bytes of its messages to rank 0 (crossings or dvr runs, shadow answers; rank 0's
    /// own stay in place): what the compositing moves.
    pub bytes_sent: u64,
    /// Its rays' work counters.
    pub stats: Stats,
}

/// What `render --json` prints of a frame over ranks: the frame's report, the file's
/// bricks, and what each rank did.
#[derive(Debug, Clone, Serialize)]
pub struct RanksReport {
    #[serde(flatten)]
    pub frame: crate::render::FrameReport,
    pub bricks: usize,
    pub ranks: Vec<RankReport>,
}

/// Refuses a view that one frame over `ranks` ranks cannot render as one process does:
/// bit for bit (iso), or within what early ray termination leaves (dvr: at most 1/512 of
/// a colour, under one 8-bit level).
pub fn check(scene: &Scene, ranks: usize) -> Result<(), Unsupported> {
    let dvr = scene.params.tf.mode == Mode::Dvr;
    let strategy = scene.params.strategy;
    let what = if dvr && scene.state.shadows {
        Some("dvr with shadows".to_string())
    } else if (dvr && strategy == Strategy::Bisect) || (!dvr && strategy != Strategy::Exact) {
        Some(format!("the `{}` strategy", strategy.as_str()))
    } else if !scene.is_single_opaque() {
        Some("several iso-surfaces, a translucent one or slices".to_string())
    } else {
        None
    };
    match what {
        Some(what) => Err(Unsupported { ranks, what }),
        None => Ok(()),
    }
}

/// Words of one crossing in a rank's message: ray, t, world point, normal, colour value,
/// first-surface depth and value.
const CROSSING_WORDS: usize = 12;
/// Words of one dvr run in a rank's message: ray, distance of its first sample, colour
/// (premultiplied), transmittance.
const RUN_WORDS: usize = 6;
/// Words of one shadow ray rank 0 sends: origin, direction, t0, t1.
const SHADOW_WORDS: usize = 8;

/// A crossing one rank found, as rank 0 reads it.
#[derive(Debug, Clone, Copy)]
struct Crossing {
    ray: usize,
    t: f64,
    world: DVec3,
    normal: DVec3,
    /// The colour field's value there (`None` where the reconstruction has no weights):
    /// rank 0 maps it to the surface's colour, so only rank 0 needs the colour map.
    colour: Option<f64>,
    first: FirstSurface,
}

impl Crossing {
    fn encode(&self, out: &mut Vec<f64>) {
        out.push(self.ray as f64);
        out.push(self.t);
        out.extend(self.world.to_array());
        out.extend(self.normal.to_array());
        out.push(f64::from(u8::from(self.colour.is_some())));
        out.push(self.colour.unwrap_or(0.0));
        out.push(f64::from(self.first.t));
        out.push(f64::from(self.first.value));
    }

    fn decode(w: &[f64]) -> Crossing {
        let v = |i: usize| DVec3::new(w[i], w[i + 1], w[i + 2]);
        Crossing {
            ray: w[0] as usize,
            t: w[1],
            world: v(2),
            normal: v(5),
            colour: (w[8] != 0.0).then_some(w[9]),
            first: FirstSurface {
                t: w[10] as f32,
                value: w[11] as f32,
            },
        }
    }
}

/// A stretch of one ray that one rank composited (dvr), as rank 0 reads it.
#[derive(Debug, Clone, Copy)]
struct Run {
    ray: usize,
    /// Distance of its first sample: where it lies on the ray.
    t: f64,
    acc: Accum,
}

impl Run {
    fn encode(&self, out: &mut Vec<f64>) {
        out.push(self.ray as f64);
        out.push(self.t);
        out.extend(self.acc.rgb);
        out.push(self.acc.transmittance);
    }

    fn decode(w: &[f64]) -> Run {
        Run {
            ray: w[0] as usize,
            t: w[1],
            acc: Accum {
                rgb: [w[2], w[3], w[4]],
                transmittance: w[5],
            },
        }
    }
}

fn to_bytes(words: &[f64]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

fn words(bytes: &[u8], rank: usize, per: usize) -> Result<Vec<f64>, PartError> {
    if !bytes.len().is_multiple_of(8 * per) {
        return Err(PartError {
            rank,
            what: format!(
                "has {} bytes, not records of {} bytes",
                bytes.len(),
                8 * per
            ),
        });
    }
    Ok(bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect())
}

/// What a camera ray sees, as rank 0 composites it.
#[derive(Debug, Clone, Copy)]
enum Seen {
    /// The clip planes keep nothing of it, or it meets nothing.
    Nothing,
    Mesh(MeshHit),
    /// The nearest crossing: rank, index in that rank's message.
    Surface(u32, u32),
    /// Dvr: the ranks' runs composited, and the mesh behind them.
    Dvr(Accum, Option<MeshHit>),
}

/// The dvr runs of every rank (`parts[rank]`: records of [`RUN_WORDS`], ray after ray, each
/// ray's front to back) composited per ray in the order of their first samples: runs lie on
/// disjoint stretches of the ray (each rank's regions are KD subtrees), so that order is
/// the ray's.
fn composite_runs(parts: &[Vec<f64>], n_rays: usize) -> Result<Vec<Accum>, PartError> {
    let mut out = vec![Accum::default(); n_rays];
    let mut at = vec![0usize; parts.len()];
    let mut here: Vec<(f64, Accum)> = Vec::new();
    for (i, slot) in out.iter_mut().enumerate() {
        here.clear();
        for (rank, part) in parts.iter().enumerate() {
            while let Some(rec) = part.get(at[rank] * RUN_WORDS..(at[rank] + 1) * RUN_WORDS) {
                // Compared as sent: a record whose ray is not an integer is out of order.
                if rec[0] != i as f64 {
                    break;
                }
                let run = Run::decode(rec);
                here.push((run.t, run.acc));
                at[rank] += 1;
            }
        }
        here.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, run) in &here {
            slot.then(run);
        }
    }
    for (rank, part) in parts.iter().enumerate() {
        if at[rank] * RUN_WORDS != part.len() {
            return Err(PartError {
                rank,
                what: format!(
                    "lists runs out of ray order or outside the frame's {n_rays} rays \
                     (record {} of {})",
                    at[rank],
                    part.len() / RUN_WORDS
                ),
            });
        }
    }
    Ok(out)
}

/// What the clip planes and meshes make of a camera ray (at rank 0).
const CLIPPED: u8 = 0;
const OPEN: u8 = 1;
const MESH: u8 = 2;

/// Renders one frame of `scene` as rank `ex.rank()` of `ex.size()`, searching the regions
/// `owned` marks ([`super::owned_regions`]). Collective: every rank calls it with the same
/// view. The rays run on `pool`'s threads; the exchanges on the calling thread (where MPI
/// was started). Rank 0 returns the frame, the same as [`crate::render::render`] gives, and every
/// rank's report; the others `None`.
pub fn render_part(
    scene: &Scene,
    owned: &[bool],
    ex: &dyn Exchange,
    pool: &Renderer,
) -> Result<Option<(Frame, Vec<RankReport>)>, PartError> {
    let start = Instant::now();
    let st = scene.state;
    let vol = scene.vol;
    let (w, h) = (st.width, st.height);
    let spp = st.spp.max(1);
    let n_rays = w as usize * h as usize * spp as usize;
    let ray_index = |x: u32, y: u32, s: u32| (((y * w + x) * spp) + s) as usize;
    pool.install(|| scene.accel.prepare(vol, scene.params.tf.mode));
    // The walk steps over the subtrees of the view's active tree that hold none of this
    // rank's regions.
    let nodes = scene.accel.active_tree(vol).map(|t| t.owned_nodes(owned));
    let nodes = nodes.as_deref();

    // 1. The first crossing of every ray in this rank's regions (iso), or its stretches
    // through them composited (dvr).
    let dvr = scene.params.tf.mode == Mode::Dvr;
    let per = if dvr { RUN_WORDS } else { CROSSING_WORDS };
    struct Row {
        crossings: Vec<f64>,
        touched: Vec<u32>,
        stats: Stats,
        /// At rank 0, per ray: whether the clip planes keep nothing of it, keep it, or
        /// keep it and a mesh is met (then the next of `meshes`): the composite needs
        /// them without tracing the meshes again.
        kinds: Vec<u8>,
        meshes: Vec<MeshHit>,
    }
    let root = ex.rank() == 0;
    let mut rows: Vec<Row> = pool.install(|| {
        (0..h)
            .into_par_iter()
            .map(|y| {
                let mut caster = RayCaster::new(scene);
                caster.restrict(owned, nodes);
                let mut crossings = Vec::new();
                let mut kinds = Vec::new();
                let mut meshes = Vec::new();
                let mut runs = Vec::new();
                for x in 0..w {
                    for s in 0..spp {
                        let (ray, jit) = caster.camera_ray(x, y, s);
                        let bounds = caster.bounds(&ray);
                        if root {
                            kinds.push(match bounds.map(|b| b.mesh) {
                                None => CLIPPED,
                                Some(None) => OPEN,
                                Some(Some(m)) => {
                                    meshes.push(m);
                                    MESH
                                }
                            });
                        }
                        let Some(bounds) = bounds else {
                            continue;
                        };
                        if dvr {
                            runs.clear();
                            caster.dvr_runs(&ray, &bounds, jit, &mut runs);
                            for &(t, acc) in &runs {
                                let ray = ray_index(x, y, s);
                                Run { ray, t, acc }.encode(&mut crossings);
                            }
                            continue;
                        }
                        let Some(p) = caster.first_crossing(&ray, &bounds, jit) else {
                            continue;
                        };
                        Crossing {
                            ray: ray_index(x, y, s),
                            t: p.t.unwrap_or_else(|| (p.world - ray.origin).dot(ray.dir)),
                            world: p.world,
                            normal: p.normal,
                            colour: p.eval.map(|e| e.colour),
                            first: caster.first_at(&ray, &p),
                        }
                        .encode(&mut crossings);
                    }
                }
                let mut touched: Vec<u32> = caster.touched().collect();
                touched.sort_unstable();
                touched.dedup();
                Row {
                    crossings,
                    touched,
                    stats: caster.stats(),
                    kinds,
                    meshes,
                }
            })
            .collect()
    });
    let mut stats = Stats::default();
    let mut touched = vec![false; vol.region_count()];
    let mut mine = Vec::new();
    let mut kinds = Vec::with_capacity(if root { n_rays } else { 0 });
    let mut meshes = Vec::new();
    for row in &mut rows {
        kinds.append(&mut row.kinds);
        meshes.append(&mut row.meshes);
        stats += row.stats;
        mine.extend_from_slice(&row.crossings);
        for &r in &row.touched {
            if let Some(t) = touched.get_mut(r as usize) {
                *t = true;
            }
        }
    }
    drop(rows);
    let mut trace_ms = start.elapsed().as_secs_f64() * 1e3;
    let message = to_bytes(&mine);
    let mut bytes_sent = message.len() as u64;
    let gathered = ex.gather(&message);
    drop(message);
    drop(mine);

    // At rank 0: the nearest crossing of each ray (iso), or its runs composited in ray
    // order (dvr).
    let mut found: Vec<Vec<f64>> = Vec::new();
    let mut best = Vec::new();
    let mut composited: Vec<Accum> = Vec::new();
    if let (true, Some(parts)) = (dvr, &gathered) {
        let parts = parts
            .iter()
            .enumerate()
            .map(|(rank, b)| words(b, rank, per))
            .collect::<Result<Vec<_>, _>>()?;
        composited = composite_runs(&parts, n_rays)?;
    } else if let Some(parts) = gathered {
        best = vec![(f64::INFINITY, u32::MAX, 0u32); n_rays];
        for (rank, bytes) in parts.iter().enumerate() {
            let part = words(bytes, rank, per)?;
            for (k, rec) in part.chunks_exact(CROSSING_WORDS).enumerate() {
                let (i, t) = (rec[0], rec[1]);
                let Some(b) = (i >= 0.0 && (i as usize) < n_rays && i.fract() == 0.0)
                    .then(|| &mut best[i as usize])
                else {
                    return Err(PartError {
                        rank,
                        what: format!("names ray {i}, not one of the frame's {n_rays}"),
                    });
                };
                // The nearest; on a tie the lower rank's.
                if t < b.0 {
                    *b = (t, rank as u32, k as u32);
                }
            }
            found.push(part);
        }
    }
    let crossing = |rank: u32, k: u32| {
        let k = k as usize;
        Crossing::decode(&found[rank as usize][k * CROSSING_WORDS..(k + 1) * CROSSING_WORDS])
    };
    // Where each ray's mesh hit is in `meshes` (only with meshes).
    let mesh_of: Vec<u32> = if root && !meshes.is_empty() {
        let mut next = 0u32;
        kinds
            .iter()
            .map(|&k| {
                let i = next;
                if k == MESH {
                    next += 1;
                }
                i
            })
            .collect()
    } else {
        Vec::new()
    };
    // What ray `i` sees, at rank 0.
    let mesh_at = |i: usize| (kinds[i] == MESH).then(|| meshes[mesh_of[i] as usize]);
    let seen = |i: usize| match kinds[i] {
        CLIPPED => Seen::Nothing,
        _ if dvr => Seen::Dvr(composited[i], mesh_at(i)),
        _ => match (best[i], mesh_at(i)) {
            ((_, rank, k), _) if rank != u32::MAX => Seen::Surface(rank, k),
            (_, Some(m)) => Seen::Mesh(m),
            _ => Seen::Nothing,
        },
    };

    // 2. Shadow rays: rank 0 sends those that reach the volume, every rank says whether
    // the surface crosses them in its regions.
    let lights = &st.lights;
    let shadows = st.shadows && !lights.is_empty();
    let mut vis: Vec<f32> = Vec::new();
    if shadows {
        let mut queries: Vec<f64> = Vec::new();
        let mut pending: Vec<usize> = Vec::new();
        if ex.rank() == 0 {
            vis = vec![1.0; n_rays * lights.len()];
            let caster = RayCaster::new(scene);
            for y in 0..h {
                for x in 0..w {
                    for s in 0..spp {
                        let i = ray_index(x, y, s);
                        let (ray, _) = caster.camera_ray(x, y, s);
                        let (p, n) = match seen(i) {
                            // A dvr view over ranks has no shadows.
                            Seen::Nothing | Seen::Dvr(..) => continue,
                            Seen::Mesh(m) => mesh_point(&ray, &m),
                            Seen::Surface(rank, k) => {
                                let c = crossing(rank, k);
                                (c.world, c.normal)
                            }
                        };
                        for (j, light) in lights.iter().enumerate() {
                            match shadow_ray(scene, p, n, light) {
                                ShadowRay::Settled(v) => vis[i * lights.len() + j] = v,
                                ShadowRay::Volume(q) => {
                                    queries.extend(q.o);
                                    queries.extend(q.d);
                                    queries.extend([q.t0, q.t1]);
                                    pending.push(i * lights.len() + j);
                                }
                            }
                        }
                    }
                }
            }
        }
        let sent = ex.broadcast(to_bytes(&queries));
        let t_answer = Instant::now();
        let queries = words(&sent, 0, SHADOW_WORDS)?;
        let parts: Vec<(Vec<u8>, Vec<u32>, Stats)> = pool.install(|| {
            queries
                .par_chunks(SHADOW_WORDS * 1024)
                .flat_map_iter(|chunk| {
                    let mut caster = RayCaster::new(scene);
                    caster.restrict(owned, nodes);
                    let a: Vec<u8> = chunk
                        .chunks_exact(SHADOW_WORDS)
                        .map(|q| {
                            let q = VolumeShadow {
                                o: [q[0], q[1], q[2]],
                                d: [q[3], q[4], q[5]],
                                t0: q[6],
                                t1: q[7],
                            };
                            u8::from(caster.shadow_occluded(&q))
                        })
                        .collect();
                    let touched: Vec<u32> = caster.touched().collect();
                    let stats = caster.stats();
                    std::iter::once((a, touched, stats))
                })
                .collect()
        });
        let answers: Vec<u8> = parts
            .into_iter()
            .flat_map(|(a, t, s)| {
                stats += s;
                for r in t {
                    if let Some(x) = touched.get_mut(r as usize) {
                        *x = true;
                    }
                }
                a
            })
            .collect();
        trace_ms += t_answer.elapsed().as_secs_f64() * 1e3;
        bytes_sent += answers.len() as u64;
        if let Some(all) = ex.gather(&answers) {
            for (rank, a) in all.iter().enumerate() {
                if a.len() != pending.len() {
                    return Err(PartError {
                        rank,
                        what: format!(
                            "answers {} shadow rays, not the {} sent",
                            a.len(),
                            pending.len()
                        ),
                    });
                }
            }
            for (q, &slot) in pending.iter().enumerate() {
                let occluded = all.iter().any(|a| a[q] != 0);
                vis[slot] = first_surface_through(scene, occluded) as f32;
            }
        }
    }

    // 3. At rank 0: every ray shaded as one process shades it, the pixels summed in
    // sample order.
    let frame = (ex.rank() == 0).then(|| {
        let bg = st.background.map(f64::from);
        let n_lights = if shadows { lights.len() } else { 0 };
        // Each row's mean colours, hit counts, depths and surface values: what the film
        // of one process resolves to, per pixel the same sum in sample order.
        type Row = (Vec<[f32; 3]>, Vec<u32>, Vec<f32>, Vec<f32>);
        let rows: Vec<Row> = pool.install(|| {
            (0..h)
                .into_par_iter()
                .map(|y| {
                    let caster = RayCaster::new(scene);
                    let mut row: Row = (
                        Vec::with_capacity(w as usize),
                        Vec::with_capacity(w as usize),
                        Vec::with_capacity(w as usize),
                        Vec::with_capacity(w as usize),
                    );
                    for x in 0..w {
                        let mut c = [0.0f64; 3];
                        let mut hits = 0u32;
                        let mut first = FirstSurface::NONE;
                        for s in 0..spp {
                            let i = ray_index(x, y, s);
                            let (ray, _) = caster.camera_ray(x, y, s);
                            let v = &vis[i * n_lights..(i + 1) * n_lights];
                            let (colour, met) = match seen(i) {
                                Seen::Dvr(acc, mesh) => {
                                    if acc.alpha() >= 0.01 {
                                        hits += 1;
                                    }
                                    let (back, met) = match mesh {
                                        Some(m) => {
                                            let (p, n) = mesh_point(&ray, &m);
                                            let met = FirstSurface {
                                                t: m.t as f32,
                                                value: f32::NAN,
                                            };
                                            (lit(scene, m.colour, n, &ray, p, v), met)
                                        }
                                        None => (bg, FirstSurface::NONE),
                                    };
                                    let back = if acc.done() { [0.0; 3] } else { back };
                                    (acc.over(back), met)
                                }
                                Seen::Nothing => (bg, FirstSurface::NONE),
                                Seen::Mesh(m) => {
                                    let (p, n) = mesh_point(&ray, &m);
                                    let met = FirstSurface {
                                        t: m.t as f32,
                                        value: f32::NAN,
                                    };
                                    (lit(scene, m.colour, n, &ray, p, v), met)
                                }
                                Seen::Surface(rank, k) => {
                                    let cr = crossing(rank, k);
                                    hits += 1;
                                    let base = base_colour(scene, cr.colour);
                                    (lit(scene, base, cr.normal, &ray, cr.world, v), cr.first)
                                }
                            };
                            if s == 0 {
                                first = met;
                            }
                            for a in 0..3 {
                                c[a] += colour[a];
                            }
                        }
                        row.0.push(film::mean_colour(c, spp));
                        row.1.push(hits);
                        row.2.push(first.t);
                        row.3.push(first.value);
                    }
                    row
                })
                .collect()
        });
        let n = w as usize * h as usize;
        let mut frame = Frame {
            width: w,
            height: h,
            rgb: Vec::with_capacity(n),
            pixel_hits: Vec::with_capacity(n),
            depth: Vec::with_capacity(n),
            surface_values: Vec::with_capacity(n),
            stats,
            rays: n_rays as u64,
            hits: 0,
        };
        for (rgb, hits, depth, values) in rows {
            frame.rgb.extend(rgb);
            frame.pixel_hits.extend(hits);
            frame.depth.extend(depth);
            frame.surface_values.extend(values);
        }
        frame.hits = frame.pixel_hits.iter().map(|&h| u64::from(h)).sum();
        frame
    });

    // Every rank's report at rank 0.
    let bricks = |mask: &[bool]| {
        let mut b = vec![false; vol.brick_count()];
        for (r, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            for id in vol.region_brick_ids(r) {
                if let Some(x) = b.get_mut(id.to_native() as usize) {
                    *x = true;
                }
            }
        }
        b.iter().filter(|x| **x).count() as u64
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let report = RankReport {
        rank: ex.rank(),
        ms,
        composite_ms: (ms - trace_ms).max(0.0),
        regions: owned.iter().filter(|o| **o).count() as u64,
        bricks_owned: bricks(owned),
        bricks_touched: bricks(&touched),
        bytes_sent,
        stats,
    };
    let reports = ex.gather(&serde_json::to_vec(&report).unwrap_or_default());
    let (Some(mut frame), Some(reports)) = (frame, reports) else {
        return Ok(None);
    };
    let mut all = Vec::new();
    for (rank, r) in reports.iter().enumerate() {
        let r: RankReport = serde_json::from_slice(r).map_err(|e| PartError {
            rank,
            what: format!("is not a report: {e}"),
        })?;
        all.push(r);
    }
    frame.stats = Stats::default();
    for r in &all {
        frame.stats += r.stats;
    }
    Ok(Some((frame, all)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{icosphere, Meshes};
    use crate::parts::{local_ranks, owned_regions};
    use crate::planes::Plane;
    use crate::view_state::ViewState;
    use crate::volume::Volume;

    /// The frame over `n` in-process ranks, and each rank's report.
    fn over_ranks(scene: &Scene, n: usize) -> (Frame, Vec<RankReport>) {
        let owned: Vec<Vec<bool>> = (0..n).map(|r| owned_regions(scene, r, n)).collect();
        let mut out = std::thread::scope(|s| {
            let handles: Vec<_> = local_ranks(n)
                .into_iter()
                .zip(&owned)
                .map(|(rank, owned)| {
                    s.spawn(move || {
                        let pool = Renderer::new(Some(2)).expect("pool");
                        render_part(scene, owned, &rank, &pool)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("rank thread").expect("frame"))
                .collect::<Vec<_>>()
        });
        assert!(
            out.iter().skip(1).all(Option::is_none),
            "only rank 0 has the frame"
        );
        out.swap_remove(0).expect("rank 0's frame")
    }

    /// A wavy shell off the centre of two nested levels: it crosses both levels, many
    /// regions and the level boundary, and shadows itself.
    fn shell_file() -> format::BrickFile {
        let shell = |p: [f64; 3]| {
            let r2: f64 = (0..3).map(|a| (p[a] - [10.3, 11.1, 9.7][a]).powi(2)).sum();
            r2.sqrt() + 0.8 * (0.7 * p[0]).sin() * (0.5 * p[1]).cos()
        };
        crate::testvol::nested(12, [0.0; 3], &[("r", &shell)], 4)
    }

    /// A sphere inside the shell.
    fn sphere() -> Meshes {
        Meshes::from_meshes(&[icosphere(glam::DVec3::new(12.0, 12.0, 12.0), 3.0, 2)])
    }

    /// A small view of the shell at `spp` samples per pixel, cut by a slanted plane when
    /// `clip`.
    fn shell_view(vol: &Volume, clip: bool, spp: u32) -> ViewState {
        let mut state = ViewState::default_for_volume(vol);
        state.iso = 6.0;
        state.width = 48;
        state.height = 40;
        state.spp = spp;
        if clip {
            state.clip = vec![Plane {
                origin: [12.0, 12.0, 12.5],
                normal: [0.3, 0.0, -1.0],
            }];
        }
        state
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// Over 1, 2, 3 and 4 ranks, with and without a mesh, shadows, a clip plane and
    /// jittered samples, the frame equals one process's bit for bit: colours, depths,
    /// surface values and hit counts.
    #[test]
    fn a_frame_over_ranks_equals_one_process_bit_for_bit() {
        let file = shell_file();
        let view = crate::testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let sphere = sphere();
        let none = Meshes::empty();
        for (case, shadows, with_mesh, clip, spp) in [
            ("plain", false, false, false, 1),
            ("shadows and mesh", true, true, false, 1),
            ("clipped, 2 samples", true, false, true, 2),
        ] {
            let mut state = shell_view(&vol, clip, spp);
            state.shadows = shadows;
            let meshes = if with_mesh { &sphere } else { &none };
            let scene = Scene::new(&vol, &state, meshes).expect("scene");
            check(&scene, 2).expect("a view ranks render");
            let serial = crate::render::render(&scene);
            assert!(
                serial.hits > 100,
                "{case}: the surface shows ({} hits)",
                serial.hits
            );
            for n in 1..=4 {
                let (frame, reports) = over_ranks(&scene, n);
                assert_eq!(frame.rgb, serial.rgb, "{case}, {n} ranks: colours");
                assert_eq!(
                    bits(&frame.depth),
                    bits(&serial.depth),
                    "{case}, {n}: depth"
                );
                assert_eq!(
                    bits(&frame.surface_values),
                    bits(&serial.surface_values),
                    "{case}, {n}: values"
                );
                assert_eq!(frame.pixel_hits, serial.pixel_hits, "{case}, {n}: hits");
                assert_eq!((frame.rays, frame.hits), (serial.rays, serial.hits));
                assert_eq!(reports.len(), n);
                let all = vol.brick_count() as u64;
                for r in &reports {
                    assert!(r.bricks_touched <= all && r.bricks_owned <= all);
                    if n > 1 {
                        assert!(r.regions < vol.region_count() as u64, "{case}: {r:?}");
                    }
                }
            }
        }
    }

    /// Dvr over 1 to 4 ranks: every 8-bit channel within one level of one process's
    /// (early ray termination is per rank), with a mesh, a clip plane, jittered samples, and
    /// the pre-integrated (`uniform`) and point-sampled `paper` strategies.
    #[test]
    fn dvr_over_ranks_is_within_one_level_of_one_process() {
        let file = shell_file();
        let view = crate::testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let sphere = sphere();
        let none = Meshes::empty();
        let level = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as i32;
        for (case, preintegrated, strategy, with_mesh, clip, spp) in [
            ("pre-integrated", true, Strategy::Uniform, false, false, 1),
            (
                "paper, mesh, clipped, 2 samples",
                false,
                Strategy::Paper,
                true,
                true,
                2,
            ),
        ] {
            let mut state = shell_view(&vol, clip, spp);
            state.mode = Mode::Dvr;
            state.transfer.sigma = 0.6;
            state.transfer.peak_opacity = 0.6;
            state.preintegrated = preintegrated;
            state.strategy = strategy;
            let meshes = if with_mesh { &sphere } else { &none };
            let scene = Scene::new(&vol, &state, meshes).expect("scene");
            check(&scene, 2).expect("a view ranks render");
            let serial = crate::render::render(&scene);
            assert!(
                serial.hits > 100,
                "{case}: the band shows ({} hits)",
                serial.hits
            );
            for n in 1..=4 {
                let (frame, reports) = over_ranks(&scene, n);
                let worst = frame
                    .rgb
                    .iter()
                    .zip(&serial.rgb)
                    .flat_map(|(a, b)| (0..3).map(move |c| (level(a[c]) - level(b[c])).abs()))
                    .max()
                    .unwrap_or(0);
                assert!(worst <= 1, "{case}, {n} ranks: {worst} levels apart");
                if n == 1 {
                    assert_eq!(frame.rgb, serial.rgb, "{case}: one rank is one process");
                }
                assert_eq!(
                    bits(&frame.depth),
                    bits(&serial.depth),
                    "{case}, {n}: depth"
                );
                assert_eq!(frame.rays, serial.rays);
                assert_eq!(frame.hits, serial.hits, "{case}, {n}: hits");
                if n > 1 {
                    assert!(
                        reports.iter().all(|r| r.stats.samples > 0),
                        "{case}: {reports:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn views_ranks_cannot_render_alike_are_refused_with_the_reason() {
        let f = |p: [f64; 3]| p[0];
        let file = crate::testvol::nested(4, [0.0; 3], &[("x", &f)], 4);
        let view = crate::testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        let none = Meshes::empty();
        let mut state = ViewState::default_for_volume(&vol);
        state.mode = Mode::Dvr;
        state.shadows = true;
        let scene = Scene::new(&vol, &state, &none).expect("scene");
        let e = check(&scene, 2).expect_err("dvr with shadows");
        assert!(e.to_string().contains("dvr with shadows"), "{e}");
        state.shadows = false;
        state.preintegrated = false;
        state.strategy = Strategy::Bisect;
        let scene = Scene::new(&vol, &state, &none).expect("scene");
        let e = check(&scene, 2).expect_err("dvr bisect");
        assert!(e.to_string().contains("`bisect` strategy"), "{e}");
        let mut state = ViewState::default_for_volume(&vol);
        state.iso_opacity = 0.5;
        let scene = Scene::new(&vol, &state, &none).expect("scene");
        let e = check(&scene, 3).expect_err("translucent");
        assert!(e.to_string().contains("3 MPI ranks"), "{e}");
        let mut state = ViewState::default_for_volume(&vol);
        state.strategy = Strategy::Bisect;
        let scene = Scene::new(&vol, &state, &none).expect("scene");
        assert!(check(&scene, 2)
            .expect_err("bisect")
            .to_string()
            .contains("bisect"));
    }
}
