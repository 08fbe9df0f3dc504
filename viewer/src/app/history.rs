//! Undo and redo of the view: snapshots of what the user changed, taken once a change has
//! settled.
//!
//! Every change of the view ends up in the window's `ViewState` — the panel's in-place
//! edits, the [`AppCommand`](super::command::AppCommand)s the window handles, the mouse
//! on the image — so the history watches that one value instead of each control: once
//! per frame the window hands it the current view, and a view that differs from the last
//! one recorded becomes a new step. While a change is still going on (a button held
//! down on a slider or the image, the wheel still turning) nothing is recorded, so a
//! whole drag is one step. Undo and redo are themselves commands (`AppCommand::Undo`,
//! `AppCommand::Redo`), handled where the window handles the others.

use std::collections::VecDeque;

use crate::mesh::MeshInstance;
use crate::view_state::ViewState;

/// Steps kept: enough for a session's worth of changes, small enough that the copies
/// (a few kilobytes each) never matter.
pub(crate) const MAX_STEPS: usize = 100;

/// What one step restores: the view state and the window's own parts of the view that
/// change with it (the pivot orbiting turns around, the meshes switched off).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Snapshot {
    pub state: ViewState,
    pub pivot: [f64; 3],
    pub hidden_meshes: Vec<MeshInstance>,
}

impl Snapshot {
    /// Whether `self` and `other` show the same view. The image size is not part of it:
    /// it follows the window, and resizing the window is not a change to undo.
    fn same_view(&self, other: &Snapshot) -> bool {
        let mut a = other.state.clone();
        a.width = self.state.width;
        a.height = self.state.height;
        a == self.state && self.pivot == other.pivot && self.hidden_meshes == other.hidden_meshes
    }
}

/// The steps before and after the view shown.
#[derive(Debug, Default)]
pub(crate) struct History {
    /// Older views, the newest last; at most [`MAX_STEPS`].
    undo: VecDeque<Snapshot>,
    /// Views undone, the most recently undone last.
    redo: Vec<Snapshot>,
    /// The view last recorded (what undo goes back from).
    current: Option<Snapshot>,
}

impl History {
    /// Forgets every step and starts from `now` (another file is open: its views do not
    /// apply to the new data).
    pub(crate) fn reset(&mut self, now: Snapshot) {
        self.undo.clear();
        self.redo.clear();
        self.current = Some(now);
    }

    /// Looks at the view shown this frame. A view that differs from the one recorded
    /// becomes a new step, unless the user is still `changing` it (a drag, the wheel):
    /// then it is looked at again next frame, so the whole gesture is one step. A new
    /// step drops the views undone.
    pub(crate) fn observe(&mut self, now: &Snapshot, changing: bool) {
        let Some(current) = &self.current else {
            self.current = Some(now.clone());
            return;
        };
        if changing || current.same_view(now) {
            return;
        }
        let old = self.current.replace(now.clone());
        if let Some(old) = old {
            self.undo.push_back(old);
            if self.undo.len() > MAX_STEPS {
                self.undo.pop_front();
            }
        }
        self.redo.clear();
    }

    /// The view before `now` (after recording `now` if it is a change not recorded yet),
    /// or `None` at the oldest step.
    pub(crate) fn undo(&mut self, now: &Snapshot) -> Option<Snapshot> {
        self.observe(now, false);
        let back = self.undo.pop_back()?;
        if let Some(cur) = self.current.replace(back.clone()) {
            self.redo.push(cur);
        }
        Some(back)
    }

    /// The view undone last, or `None` when nothing was undone since the last change.
    pub(crate) fn redo(&mut self, now: &Snapshot) -> Option<Snapshot> {
        self.observe(now, false);
        let forward = self.redo.pop()?;
        if let Some(cur) = self.current.replace(forward.clone()) {
            self.undo.push_back(cur);
        }
        Some(forward)
    }

    pub(crate) fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }

    pub(crate) fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view_state::FieldRange;

    fn snap(iso: f64) -> Snapshot {
        let q = [FieldRange {
            name: "q".into(),
            min: -1.0,
            max: 1.0,
        }];
        let mut state = ViewState::default_for([0.0; 3], [1.0; 3], &q);
        state.iso = iso;
        Snapshot {
            state,
            pivot: [0.0; 3],
            hidden_meshes: Vec::new(),
        }
    }

    #[test]
    fn undo_and_redo_walk_the_steps() {
        let mut h = History::default();
        h.reset(snap(0.1));
        h.observe(&snap(0.2), false);
        h.observe(&snap(0.3), false);
        assert_eq!(h.undo(&snap(0.3)).map(|s| s.state.iso), Some(0.2));
        assert_eq!(h.undo(&snap(0.2)).map(|s| s.state.iso), Some(0.1));
        assert!(h.undo(&snap(0.1)).is_none());
        assert_eq!(h.redo(&snap(0.1)).map(|s| s.state.iso), Some(0.2));
        // A new change drops what was undone.
        h.observe(&snap(0.5), false);
        assert!(h.redo(&snap(0.5)).is_none());
        assert_eq!(h.undo(&snap(0.5)).map(|s| s.state.iso), Some(0.2));
    }

    #[test]
    fn a_gesture_is_one_step_and_resizing_is_none() {
        let mut h = History::default();
        h.reset(snap(0.1));
        for i in 2..10 {
            h.observe(&snap(f64::from(i) * 0.1), true);
        }
        h.observe(&snap(0.9), false);
        let mut resized = snap(0.9);
        resized.state.width += 100;
        h.observe(&resized, false);
        assert_eq!(h.undo(&resized).map(|s| s.state.iso), Some(0.1));
        assert!(!h.can_undo());
    }

    #[test]
    fn undo_records_a_change_still_going_on() {
        let mut h = History::default();
        h.reset(snap(0.1));
        h.observe(&snap(0.4), true);
        assert_eq!(h.undo(&snap(0.4)).map(|s| s.state.iso), Some(0.1));
        assert_eq!(h.redo(&snap(0.1)).map(|s| s.state.iso), Some(0.4));
    }

    #[test]
    fn the_history_is_capped() {
        let mut h = History::default();
        h.reset(snap(0.0));
        for i in 1..=(MAX_STEPS + 20) {
            h.observe(&snap(i as f64), false);
        }
        let mut n = 0;
        let mut now = snap((MAX_STEPS + 20) as f64);
        while let Some(s) = h.undo(&now) {
            now = s;
            n += 1;
        }
        assert_eq!(n, MAX_STEPS);
        assert_eq!(now.state.iso, 20.0);
    }
}
