//! A view's acceleration: what its rays walk besides the file itself.
//!
//! Three things depend on the view and not only on the file: the KD-tree packed with the
//! iso field's value ranges (rays skip subtrees by them), the tree of the regions that can
//! hold the iso value (`crate::active`, what iso-surface rays walk), and the box of the
//! regions that can contribute to the band (rays are clipped to it). An [`Accel`] holds
//! them for one [`AccelKey`], the settings that decide them; a scene owns one
//! ([`crate::scene::Scene`]), and the ray code takes them from it, so no ray asks which
//! field or iso value a tree was built for. The [`crate::volume::Volume`] stays the file
//! alone, shared by every view.
//!
//! A renderer that renders one view after another keeps the last few in an
//! [`AccelCache`], so that orbiting the camera (same key) builds nothing and a new iso
//! value keeps its field's packed tree. The cache belongs to the one thread that renders;
//! it has no lock.

use std::sync::{Arc, OnceLock};

use crate::active::ActiveTree;
use crate::packed::Packed;
use crate::transfer::Mode;
use crate::volume::Volume;

/// The settings that decide a view's acceleration. Two views with equal keys (`==`) can
/// share one [`Accel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelKey {
    /// Index of the iso field: whose packed tree, whose ranges.
    pub field: usize,
    /// The iso value: which regions the active tree holds.
    pub iso: f64,
    /// The band `[lo, hi]` that contributes (the iso value alone in iso mode): the clip box.
    pub band: (f64, f64),
}

/// A view's acceleration for one [`AccelKey`]: built for one volume, and only used with
/// it (a scene pairs them).
///
/// The clip box is found when a scene first asks for it (as it is made), by a walk of the
/// packed tree that skips the subtrees outside the band, so making a scene packs the tree
/// its frames walk anyway (what it replaced, a pass over a table of every region, cost
/// more). The active tree is built when first needed: by `Accel::prepare` before a
/// frame's tiles, on the render pool, or by the first ray that asks (a `--pixel` trace, a
/// pick in the window, a test). So a dvr view never builds the active tree unless a pick
/// asks for the iso-surface.
pub struct Accel {
    key: AccelKey,
    /// The file's tree packed with the iso field's ranges; `None` inside for a field the
    /// file does not have (walks then read the archived tree).
    packed: OnceLock<Option<Arc<Packed>>>,
    /// The regions that can hold the iso value; `None` inside when the file's tree cannot
    /// be walked as a tree (iso rays then walk the file's tree).
    active: OnceLock<Option<Arc<ActiveTree>>>,
    /// Local box of the regions whose range meets the band (`min > max`: none does),
    /// found from the packed tree when first asked for.
    clip: OnceLock<([f64; 3], [f64; 3])>,
}

impl Accel {
    /// The acceleration of `key`, for one volume: the methods that build its trees take
    /// that volume, when first needed.
    pub fn new(key: AccelKey) -> Accel {
        Accel::reusing(key, None)
    }

    /// [`Accel::new`], taking from `like` (an acceleration of the same volume) the trees
    /// it has built that `key` also needs: the packed tree of the same field, the active
    /// tree of the same field and iso value.
    fn reusing(key: AccelKey, like: Option<&Accel>) -> Accel {
        let accel = Accel {
            key,
            packed: OnceLock::new(),
            active: OnceLock::new(),
            clip: OnceLock::new(),
        };
        if let Some(like) = like.filter(|l| l.key.field == key.field) {
            if let Some(p) = like.packed.get() {
                let _ = accel.packed.set(p.clone());
            }
            if like.key.band == key.band {
                if let Some(&c) = like.clip.get() {
                    let _ = accel.clip.set(c);
                }
            }
            if like.key.iso == key.iso {
                if let Some(t) = like.active.get() {
                    let _ = accel.active.set(t.clone());
                }
            }
        }
        accel
    }

    /// An acceleration of `key` whose active tree is `tree` (tests compare trees).
    #[cfg(test)]
    pub(crate) fn with_active(key: AccelKey, tree: Arc<ActiveTree>) -> Accel {
        let accel = Accel::new(key);
        let _ = accel.active.set(Some(tree));
        accel
    }

    /// The settings this acceleration is for.
    pub fn key(&self) -> AccelKey {
        self.key
    }

    /// Local box of the regions that can contribute to the band (rays are clipped to it;
    /// `min > max` when none can), found on first call from the packed tree (which packs
    /// it, if no frame has yet).
    pub fn clip(&self, vol: &Volume) -> ([f64; 3], [f64; 3]) {
        *self.clip.get_or_init(|| {
            let (lo, hi) = self.key.band;
            match self.packed(vol) {
                Some(p) => vol.active_box_in(p, self.key.field, lo, hi),
                None => ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
            }
        })
    }

    /// Builds the trees a frame in `mode` walks before its first tile: the packed tree,
    /// and in iso mode the active tree with its masks on the current rayon pool. Called
    /// where no job of that pool can be waiting for them (the frame loop, before it starts
    /// the tiles): a tile that asked meanwhile builds its own copy without the pool, and
    /// the first tree kept wins, so nothing waits on a lock while pool jobs run.
    pub(crate) fn prepare(&self, vol: &Volume, mode: Mode) {
        let packed = self.packed(vol);
        if mode != Mode::Iso || self.active.get().is_some() {
            return;
        }
        let tree = packed
            .and_then(|p| ActiveTree::build(vol, p, self.key.field, self.key.iso, true))
            .map(Arc::new);
        let _ = self.active.set(tree);
    }

    /// The file's tree packed with the iso field's ranges (packed on first need).
    pub(crate) fn packed(&self, vol: &Volume) -> Option<&Packed> {
        self.packed
            .get_or_init(|| vol.packed(self.key.field))
            .as_deref()
    }

    /// The regions that can hold the iso value (built on first need, without the render
    /// pool: see [`Accel::prepare`]).
    pub(crate) fn active_tree(&self, vol: &Volume) -> Option<&ActiveTree> {
        self.active
            .get_or_init(|| {
                let packed = self.packed(vol)?;
                ActiveTree::build(vol, packed, self.key.field, self.key.iso, false).map(Arc::new)
            })
            .as_deref()
    }
}

/// How many accelerations an [`AccelCache`] keeps: a view and a few it flips between (an
/// iso value dragged back and forth, the preview and the full frame share one).
/// Each iso-surface of a view has one, so it keeps a view's every surface too.
pub(crate) const KEEP: usize = 4 + crate::view_state::MAX_ISO_SURFACES;

/// The accelerations of the last few views of one volume, newest last, for a renderer
/// that renders one view after another. Owned by that renderer's thread (no lock); a
/// renderer that changes files starts a new cache ([`AccelCache::clear`]).
#[derive(Default)]
pub struct AccelCache {
    kept: Vec<Arc<Accel>>,
}

impl AccelCache {
    /// The acceleration of `key` in the cache's volume: a kept one with an equal key,
    /// else a new one that takes what it can from the newest kept one of the same field.
    pub fn get(&mut self, key: AccelKey) -> Arc<Accel> {
        if let Some(i) = self.kept.iter().position(|a| a.key == key) {
            let a = self.kept.remove(i);
            self.kept.push(Arc::clone(&a));
            return a;
        }
        let like = self.kept.iter().rev().find(|a| a.key.field == key.field);
        let a = Arc::new(Accel::reusing(key, like.map(|a| &**a)));
        if self.kept.len() == KEEP {
            self.kept.remove(0);
        }
        self.kept.push(Arc::clone(&a));
        a
    }

    /// Forgets every kept acceleration (their volume is no longer rendered).
    pub fn clear(&mut self) {
        self.kept.clear();
    }
}
