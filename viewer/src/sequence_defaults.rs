//! What the frames of a sequence get when the user did not choose (issue 26): each
//! frame's iso value, and the one camera all frames share.
//!
//! A sequence shares one view so that colours and the camera compare across frames, and
//! the default iso value comes from the sequence's range. A flow that decays or grows can
//! leave one frame's whole iso field below (or above) that value, and the frame would be
//! an empty picture with nothing said. Such a frame takes its own default instead
//! ([`IsoRule::SharedUnlessEmpty`]), and `--iso-per-frame` gives every frame its own
//! ([`IsoRule::PerFrame`]). The test looks at the frames' field ranges, which each file's
//! header holds (see [`crate::sequence::SequenceInfo::frames`]), not at their cells: it
//! costs nothing on thousands of frames. The rule lives here, not in `qbricks-view
//! render`, so the window's sequence player can apply the same one.

use std::path::PathBuf;

use crate::sequence::{FrameSummary, SequenceInfo};
use crate::view_state::{default_iso, FieldRange, ViewState};

/// A shared iso value closer than this fraction of a frame's range to one of its ends
/// leaves the frame "nearly empty": a speck at the field's peak, or nothing. Q's default
/// (10 % of the positive maximum) lies tens of percent of the range inside it, so only a
/// frame whose peak dropped to about the shared value switches.
pub const NEARLY_EMPTY: f64 = 0.02;

/// Most surface boxes [`frame_surfaces`] fits the camera to; beyond, each frame counts
/// with its surface's bounding box only, so a long sequence of large frames does not
/// spend longer placing the camera than rendering.
const MAX_BOXES: usize = 200_000;

/// How each frame's iso value is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IsoRule {
    /// `--iso` or a state file chose it: every frame keeps it, even one it leaves empty
    /// (the value may be the point of the figure).
    Given,
    /// The sequence's default in every frame, except a frame it leaves nearly empty (see
    /// [`NEARLY_EMPTY`]), which takes its own default.
    SharedUnlessEmpty,
    /// `--iso-per-frame`: every frame its own default, as if it were opened alone.
    PerFrame,
}

/// `--iso-per-frame` together with `--iso`: two answers to one question.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("--iso-per-frame takes each frame's own default iso value, --iso gives one for every frame: give one of them")]
pub struct IsoRuleConflict;

impl IsoRule {
    /// The rule for flags: `iso_given` (`--iso`), `from_state` (a state file, whose iso
    /// value is the user's), `per_frame` (`--iso-per-frame`, which overrides a state
    /// file's value as any flag does).
    pub fn new(
        iso_given: bool,
        from_state: bool,
        per_frame: bool,
    ) -> Result<IsoRule, IsoRuleConflict> {
        match (iso_given, from_state, per_frame) {
            (true, _, true) => Err(IsoRuleConflict),
            (_, _, true) => Ok(IsoRule::PerFrame),
            (false, false, false) => Ok(IsoRule::SharedUnlessEmpty),
            _ => Ok(IsoRule::Given),
        }
    }

    /// The rule in words, for the start of a run (`state`: the shared view).
    pub fn describe(self, state: &ViewState) -> String {
        let (field, iso) = (&state.iso_field, short(state.iso));
        match self {
            IsoRule::Given => format!("iso {field} = {iso} in every frame, as given"),
            IsoRule::SharedUnlessEmpty => format!(
                "iso {field} = {iso} in every frame (the default for the sequence's range), \
                 except a frame it leaves nearly empty, which takes its own default \
                 (--iso-per-frame: every frame its own)"
            ),
            IsoRule::PerFrame => {
                format!("iso {field}: each frame's own default (--iso-per-frame)")
            }
        }
    }
}

/// A frame that does not take the shared iso value, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameIso {
    pub frame: u64,
    pub field: String,
    pub iso: f64,
    /// The dvr band's σ that goes with it (8 % of the value, as for a file alone).
    pub sigma: f64,
    pub why: OwnIso,
}

/// Why a frame takes its own default iso value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OwnIso {
    /// `--iso-per-frame`.
    Asked,
    Above {
        shared: f64,
        max: f64,
    },
    Below {
        shared: f64,
        min: f64,
    },
    NearMax {
        shared: f64,
        max: f64,
    },
    NearMin {
        shared: f64,
        min: f64,
    },
}

impl std::fmt::Display for OwnIso {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let pct = NEARLY_EMPTY * 100.0;
        match *self {
            OwnIso::Asked => write!(f, "--iso-per-frame"),
            // Four digits may not tell the two apart (a frame whose peak is the value).
            OwnIso::Above { shared, max } if short(shared) == short(max) => {
                write!(f, "the sequence's {} is its maximum", short(shared))
            }
            OwnIso::Above { shared, max } => write!(
                f,
                "the sequence's {} is above its maximum {}",
                short(shared),
                short(max)
            ),
            OwnIso::Below { shared, min } => write!(
                f,
                "the sequence's {} is below its minimum {}",
                short(shared),
                short(min)
            ),
            OwnIso::NearMax { shared, max } => write!(
                f,
                "the sequence's {} is within {pct} % of its range of its maximum {}",
                short(shared),
                short(max)
            ),
            OwnIso::NearMin { shared, min } => write!(
                f,
                "the sequence's {} is within {pct} % of its range of its minimum {}",
                short(shared),
                short(min)
            ),
        }
    }
}

impl std::fmt::Display for FrameIso {
    /// `frame 7: iso q = 0.0123 (the frame's own default; the sequence's 0.05 is above
    /// its maximum 0.031)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sep = if self.why == OwnIso::Asked {
            ", "
        } else {
            "; "
        };
        write!(
            f,
            "frame {}: iso {} = {} (the frame's own default{sep}{})",
            self.frame,
            self.field,
            short(self.iso),
            self.why
        )
    }
}

impl FrameIso {
    /// Puts this frame's value into its copy of the shared view; `band_follows`: the
    /// dvr band is the default's (not a state file's), so its width follows the value.
    pub fn apply(&self, state: &mut ViewState, band_follows: bool) {
        state.iso = self.iso;
        if band_follows {
            state.transfer.sigma = self.sigma;
        }
    }
}

/// Whether the iso value `iso` leaves a field of range `f` nearly empty, and how; `None`
/// for a range that is not finite or is a single value (nothing better to offer).
pub fn nearly_empty(iso: f64, f: &FieldRange) -> Option<OwnIso> {
    let (min, max) = (f64::from(f.min), f64::from(f.max));
    if !(min.is_finite() && max.is_finite() && iso.is_finite() && max > min) {
        return None;
    }
    let margin = NEARLY_EMPTY * (max - min);
    if iso > max {
        Some(OwnIso::Above { shared: iso, max })
    } else if iso < min {
        Some(OwnIso::Below { shared: iso, min })
    } else if max - iso < margin {
        Some(OwnIso::NearMax { shared: iso, max })
    } else if iso - min < margin {
        Some(OwnIso::NearMin { shared: iso, min })
    } else {
        None
    }
}

/// The frame's own iso value under `rule`, when it does not take the shared one in
/// `state`; `None` also for a frame without the iso field (its render fails on that).
pub fn frame_iso(rule: IsoRule, state: &ViewState, frame: &FrameSummary) -> Option<FrameIso> {
    let f = frame.fields.iter().find(|f| f.name == state.iso_field)?;
    let why = match rule {
        IsoRule::Given => return None,
        IsoRule::PerFrame => OwnIso::Asked,
        IsoRule::SharedUnlessEmpty => nearly_empty(state.iso, f)?,
    };
    let (iso, sigma) = default_iso(f);
    Some(FrameIso {
        frame: frame.frame,
        field: f.name.clone(),
        iso,
        sigma,
        why,
    })
}

/// [`frame_iso`] for every frame the survey opened, in frame order: the frames that take
/// their own value.
pub fn frame_isos(rule: IsoRule, state: &ViewState, info: &SequenceInfo) -> Vec<FrameIso> {
    info.frames
        .iter()
        .filter_map(|f| frame_iso(rule, state, f))
        .collect()
}

/// What [`frame_surfaces`] pointed the camera at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framed {
    /// The union of the iso surfaces of this many frames (those that have one).
    Surfaces(usize),
    /// No frame has a surface at its iso value: the union of the frames' data boxes.
    Data,
}

/// Points the one camera of a sequence at the union of the frames' iso surfaces, each at
/// the value `rule` gives that frame: the whole path of the structure stays in view and
/// the camera does not jump between frames, as a movie needs, while the structure fills
/// the picture far better than the data's box (the iso surface of a wake is a fraction of
/// its domain). `frames` should be every frame of the sequence, not only those rendered,
/// so that a movie rendered in parts (`--frames`) has one camera. One pass over every
/// frame's cells before the first is drawn, a fraction of a render. Frames that do not
/// open are left out (their render names the error).
pub fn frame_surfaces(
    state: &mut ViewState,
    frames: &[(u64, PathBuf)],
    rule: IsoRule,
    info: &SequenceInfo,
) -> Framed {
    // Framing reads every brick: checked at open.
    let options = format::OpenOptions {
        verify_checksum: false,
        structure: format::Structure::AtOpen,
    };
    // Per frame with a surface: its boxes (world frame) when there are at most
    // `MAX_BOXES` (more make the total pass it anyway), their count and their union.
    type FrameBoxes = (Vec<([f64; 3], [f64; 3])>, usize, ([f64; 3], [f64; 3]));
    let mut per_frame: Vec<FrameBoxes> = Vec::new();
    for (frame, path) in frames {
        let Ok(view) = format::BrickFileView::open_with(path, &options) else {
            continue;
        };
        let Ok(vol) = crate::volume::Volume::new(&view) else {
            continue;
        };
        let mut s = state.clone();
        let summary = FrameSummary {
            frame: *frame,
            bounds: (vol.to_world(vol.bounds_min), vol.to_world(vol.bounds_max)),
            fields: vol.fields.clone(),
        };
        if let Some(o) = frame_iso(rule, state, &summary) {
            o.apply(&mut s, false);
        }
        let boxes = s.surface_boxes(&vol);
        let (mut list, mut count) = (Vec::new(), 0usize);
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        boxes.for_each(&vol, |a, b| {
            let (a, b) = (vol.to_world(a), vol.to_world(b));
            count += 1;
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
            if count <= MAX_BOXES {
                list.push((a, b));
            }
        });
        if count > 0 {
            per_frame.push((list, count, (lo, hi)));
        }
    }
    if per_frame.is_empty() {
        let (lo, hi) = info.bounds.unwrap_or(([0.0; 3], [1.0; 3]));
        state.frame_boxes(&[(lo, hi)]);
        return Framed::Data;
    }
    let total: usize = per_frame.iter().map(|f| f.1).sum();
    let framed = per_frame.len();
    let boxes: Vec<([f64; 3], [f64; 3])> = if total > MAX_BOXES {
        per_frame.iter().map(|f| f.2).collect()
    } else {
        per_frame.into_iter().flat_map(|f| f.0).collect()
    };
    state.frame_boxes(&boxes);
    Framed::Surfaces(framed)
}

/// `x` with four significant digits and no trailing zeros (`0.0123`, `3.4e-7`), for
/// messages: a value read from an `f32` range prints with a dozen noise digits otherwise.
pub fn short(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    let exp = x.abs().log10().floor() as i32;
    if (-4..6).contains(&exp) {
        let decimals = (3 - exp).max(0) as usize;
        let s = format!("{x:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        let s = format!("{x:.3e}");
        match s.split_once('e') {
            Some((m, e)) if m.contains('.') => {
                format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(min: f32, max: f32) -> FieldRange {
        FieldRange {
            name: "q".into(),
            min,
            max,
        }
    }

    fn summary(frame: u64, min: f32, max: f32) -> FrameSummary {
        FrameSummary {
            frame,
            bounds: ([0.0; 3], [1.0; 3]),
            fields: vec![q(min, max)],
        }
    }

    #[test]
    fn only_a_frame_the_shared_value_leaves_empty_takes_its_own() {
        let shared = ViewState::default_for([0.0; 3], [1.0; 3], &[q(-1.0, 0.5)]);
        assert!((shared.iso - 0.05).abs() < 1e-9);
        let rule = IsoRule::new(false, false, false).expect("rule");
        assert_eq!(rule, IsoRule::SharedUnlessEmpty);
        // Half the peak: the surface shrinks but is there.
        assert_eq!(frame_iso(rule, &shared, &summary(1, -0.5, 0.25)), None);
        // A tenth of the peak: the shared value is the frame's maximum, or above it.
        let own = frame_iso(rule, &shared, &summary(2, -0.1, 0.04)).expect("own");
        assert!((own.iso - 0.004).abs() < 1e-6, "{own:?}");
        assert_eq!(
            own.to_string(),
            "frame 2: iso q = 0.004 (the frame's own default; the sequence's 0.05 is above \
             its maximum 0.04)"
        );
        let near = frame_iso(rule, &shared, &summary(3, -1.0, 0.06)).expect("near");
        assert!(matches!(near.why, OwnIso::NearMax { .. }), "{near:?}");
        let below = frame_iso(rule, &shared, &summary(4, 0.2, 0.9)).expect("below");
        assert!(matches!(below.why, OwnIso::Below { .. }), "{below:?}");
        // A frame without the field, or with a constant one, keeps the shared value.
        let other = FrameSummary {
            fields: vec![],
            ..summary(5, 0.0, 1.0)
        };
        assert_eq!(frame_iso(rule, &shared, &other), None);
        assert_eq!(frame_iso(rule, &shared, &summary(6, 0.3, 0.3)), None);
    }

    #[test]
    fn given_values_stay_and_per_frame_takes_every_frame_its_own() {
        let shared = ViewState::default_for([0.0; 3], [1.0; 3], &[q(-1.0, 0.5)]);
        for given in [
            IsoRule::new(true, false, false),
            IsoRule::new(false, true, false),
        ] {
            let given = given.expect("rule");
            assert_eq!(given, IsoRule::Given);
            assert_eq!(frame_iso(given, &shared, &summary(2, -0.1, 0.01)), None);
        }
        let per = IsoRule::new(false, true, true).expect("per-frame over a state file");
        let own = frame_iso(per, &shared, &summary(1, -1.0, 0.5)).expect("own");
        assert_eq!(own.why, OwnIso::Asked);
        assert!(own
            .to_string()
            .ends_with("(the frame's own default, --iso-per-frame)"));
        assert_eq!(IsoRule::new(true, false, true), Err(IsoRuleConflict));
    }

    #[test]
    fn short_numbers() {
        assert_eq!(short(0.012_345_678), "0.01235");
        assert_eq!(short(0.05), "0.05");
        assert_eq!(short(0.342_382_431_030_273_44), "0.3424");
        assert_eq!(short(1234.56), "1235");
        assert_eq!(short(-3.4e-7), "-3.4e-7");
        assert_eq!(short(2.0e9), "2e9");
        assert_eq!(short(0.0), "0");
    }
}
