//! Playing a frame sequence in the window: which frame is shown, play/pause and its pace.
//! Pure state (no egui), so the stepping rules are tested without a window.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Slowest and fastest playback, frames per second.
pub(crate) const FPS_RANGE: std::ops::RangeInclusive<f32> = 0.5..=60.0;

/// The frames of a sequence opened in the window and the playback over them.
#[derive(Debug, Clone)]
pub struct Player {
    /// The pattern as given (`out/frame_####.qbk`), for the panel.
    pub pattern: String,
    /// Frame numbers and files, in order.
    pub frames: Vec<(u64, PathBuf)>,
    /// Index into `frames` of the frame shown (or being opened).
    pub index: usize,
    pub playing: bool,
    pub fps: f32,
    /// When the current frame was first on screen; playback waits for it, so a slow frame
    /// is shown for its time rather than skipped.
    shown_at: Option<Instant>,
}

impl Player {
    /// A stopped player on the first frame, at 4 frames per second.
    pub(crate) fn new(pattern: String, frames: Vec<(u64, PathBuf)>) -> Player {
        Player {
            pattern,
            frames,
            index: 0,
            playing: false,
            fps: 4.0,
            shown_at: None,
        }
    }

    /// Number of the frame shown.
    pub fn frame(&self) -> u64 {
        self.frames.get(self.index).map_or(0, |f| f.0)
    }

    pub(crate) fn path(&self) -> Option<&Path> {
        self.frames.get(self.index).map(|f| f.1.as_path())
    }

    /// Goes to frame index `i` (clamped); returns whether it changed.
    pub(crate) fn seek(&mut self, i: usize) -> bool {
        let i = i.min(self.frames.len().saturating_sub(1));
        let changed = i != self.index;
        self.index = i;
        if changed {
            self.shown_at = None;
        }
        changed
    }

    /// The next frame, after the last the first (playback loops).
    pub(crate) fn step_forward(&mut self) -> bool {
        let n = self.frames.len().max(1);
        self.seek((self.index + 1) % n)
    }

    /// The previous frame, before the first the last.
    pub(crate) fn step_back(&mut self) -> bool {
        let n = self.frames.len().max(1);
        self.seek((self.index + n - 1) % n)
    }

    pub(crate) fn toggle(&mut self) {
        self.playing = !self.playing;
        self.shown_at = None;
    }

    /// Called once per UI frame with whether an image of the current frame is on screen;
    /// while playing, moves to the next frame once the current one has been on screen
    /// for `1/fps`. Returns whether it moved.
    pub(crate) fn tick(&mut self, now: Instant, current_on_screen: bool) -> bool {
        if !self.playing || self.frames.len() < 2 {
            return false;
        }
        if !current_on_screen {
            return false;
        }
        let since = *self.shown_at.get_or_insert(now);
        let fps = self.fps.clamp(*FPS_RANGE.start(), *FPS_RANGE.end());
        if now.duration_since(since) >= Duration::from_secs_f32(1.0 / fps) {
            self.step_forward()
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn player(n: u64) -> Player {
        Player::new(
            "f_####.qbk".into(),
            (1..=n)
                .map(|f| (f, PathBuf::from(format!("f_{f:04}.qbk"))))
                .collect(),
        )
    }

    #[test]
    fn stepping_wraps_and_seeking_clamps() {
        let mut p = player(3);
        assert_eq!(p.frame(), 1);
        assert!(p.step_back());
        assert_eq!(p.frame(), 3);
        assert!(p.step_forward());
        assert_eq!(p.frame(), 1);
        assert!(p.seek(10));
        assert_eq!(p.frame(), 3);
        assert!(!p.seek(2));
        assert_eq!(p.path(), Some(Path::new("f_0003.qbk")));
        let mut one = player(1);
        assert!(!one.step_forward());
    }

    #[test]
    fn playback_waits_for_each_frame_to_be_on_screen_for_its_time() {
        let mut p = player(3);
        let t0 = Instant::now();
        let ms = |m| t0 + Duration::from_millis(m);
        // Paused: nothing moves.
        assert!(!p.tick(ms(1000), true));
        p.toggle();
        p.fps = 4.0;
        // Not on screen yet: wait, however long it takes.
        assert!(!p.tick(ms(0), false));
        assert!(!p.tick(ms(5000), false));
        // On screen from 5000 ms: moves at 5250.
        assert!(!p.tick(ms(5000), true));
        assert!(!p.tick(ms(5200), true));
        assert!(p.tick(ms(5250), true));
        assert_eq!(p.frame(), 2);
        // The next frame's clock starts when it is on screen.
        assert!(!p.tick(ms(5260), true));
        assert!(p.tick(ms(5510), true));
        assert!(!p.tick(ms(5800), true));
        assert!(p.tick(ms(6050), true));
        assert_eq!(p.frame(), 1, "loops");
        p.toggle();
        assert!(!p.tick(ms(9000), true));
    }
}
