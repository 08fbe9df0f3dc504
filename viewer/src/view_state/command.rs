//! Changes to a view state that follow a rule, applied in one place.
//!
//! Most settings are plain values (a step, a colour, a width) that any caller may set. A
//! few carry a rule: a new iso field starts over from that field's range, a new colour
//! field gets a colour map over its range, an iso value drags the dvr band's width along.
//! The window's panel and the command-line flags ([`super::Overrides`]) both express
//! those changes as [`ViewCommand`]s and hand them to [`ViewState::apply`], so the window
//! and `render --iso-field` cannot drift apart (they did: choosing speed in the window
//! kept Q's iso value, and the picture went empty).

use format::sequence::FieldRange;

use super::{default_iso, ViewState};
use crate::colormap::ColorMap;
use crate::fields::UnknownField;
use crate::overlay::Overlays;
use crate::palette::PaletteSpec;

/// A change to a view state that follows a rule (see the module's docs).
#[derive(Debug, Clone, PartialEq)]
pub enum ViewCommand {
    /// Take the iso-surface (or dvr band) of the field called `name`. A field that
    /// changes starts over from its range: the iso value and band width of
    /// `default_iso`, since a value meant for another field shows nothing useful. With
    /// `keep_iso` the caller chose the iso value itself (`--iso` beside `--iso-field`), so
    /// only the field changes. Naming the current field changes nothing.
    IsoField { name: String, keep_iso: bool },
    /// Colour by the field called `name`. A field that changes gets a colour map spread
    /// over its range (`ColorMap::default_for_range`); naming the current field keeps
    /// the map, even a hand-made one.
    ColourField { name: String },
    /// Set the iso value. With `band_follows` the dvr band's width follows it (8 % of it,
    /// [`ViewState::set_iso`]), as in a view the program made; without, the band is kept,
    /// as the user set it in a view state file.
    Iso { value: f64, band_follows: bool },
    /// Colour the colour field with `palette` over `range` (`None`: the current map's
    /// range), centred on `centre` for a diverging palette, spaced in log10 with `log`
    /// (see [`PaletteSpec::colour_map`]). The field stays; the map is rebuilt.
    ColourScale {
        palette: PaletteSpec,
        range: Option<(f32, f32)>,
        centre: Option<f32>,
        log: bool,
    },
    /// Show the overlays `overlays` (see [`crate::overlay`]).
    Overlays(Overlays),
}

impl ViewState {
    /// Applies `command`, finding field names in `fields`: the fields and ranges of the
    /// data shown (a file's, or a whole sequence's, so that every frame starts from the
    /// same range). A name the data lacks is refused, naming the view-state key it would
    /// set (`iso_field`, `colormap.field`), and the state is left as it was.
    pub fn apply(
        &mut self,
        command: &ViewCommand,
        fields: &[FieldRange],
    ) -> Result<(), UnknownField> {
        match command {
            ViewCommand::IsoField { name, keep_iso } => {
                let (_, f) =
                    crate::fields::find(fields, name).map_err(|e| e.named_by("iso_field"))?;
                if *name != self.iso_field {
                    self.iso_field = name.clone();
                    if !keep_iso {
                        // The other surfaces' values belong to the old field too.
                        self.more_isos.clear();
                        let (iso, sigma) = default_iso(f);
                        self.iso = iso;
                        self.transfer.sigma = sigma;
                    }
                }
            }
            ViewCommand::ColourField { name } => {
                let (_, f) =
                    crate::fields::find(fields, name).map_err(|e| e.named_by("colormap.field"))?;
                if *name != self.colormap.field {
                    self.colormap = ColorMap::default_for_range(name, f.min, f.max);
                }
            }
            ViewCommand::Iso {
                value,
                band_follows,
            } => {
                if *band_follows {
                    self.set_iso(*value);
                } else {
                    self.iso = *value;
                }
            }
            ViewCommand::ColourScale {
                palette,
                range,
                centre,
                log,
            } => {
                let (lo, hi) = range.unwrap_or_else(|| self.colormap.range());
                self.colormap = palette.colour_map(&self.colormap.field, lo, hi, *centre, *log);
            }
            ViewCommand::Overlays(o) => self.overlays = *o,
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields() -> Vec<FieldRange> {
        [
            ("q", -2.0, 0.5),
            ("speed", 0.0, 0.08),
            ("density", 0.0, 2.0),
        ]
        .map(|(name, min, max)| FieldRange {
            name: name.into(),
            min,
            max,
        })
        .to_vec()
    }

    /// A new iso field starts from its own range whatever the view held (the window
    /// after a hand-set iso value, a state file's value), a new colour field gets a map
    /// over its range, and an unknown name is refused with the state left alone.
    #[test]
    fn a_new_field_starts_over_from_its_range() {
        let fields = fields();
        let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields);
        s.set_iso(0.25);
        let speed = ViewCommand::IsoField {
            name: "speed".into(),
            keep_iso: false,
        };
        s.apply(&speed, &fields).expect("known");
        assert_eq!(s.iso_field, "speed");
        assert_eq!((s.iso, s.transfer.sigma), default_iso(&fields[1]));
        // Again: nothing changes, not even a value set meanwhile.
        s.apply(
            &ViewCommand::Iso {
                value: 0.06,
                band_follows: false,
            },
            &fields,
        )
        .expect("iso");
        let kept = s.clone();
        s.apply(&speed, &fields).expect("known");
        assert_eq!(s, kept);
        s.apply(
            &ViewCommand::ColourField {
                name: "density".into(),
            },
            &fields,
        )
        .expect("known");
        assert_eq!(s.colormap, ColorMap::default_for_range("density", 0.0, 2.0));
        let e = s
            .apply(
                &ViewCommand::IsoField {
                    name: "w".into(),
                    keep_iso: false,
                },
                &fields,
            )
            .expect_err("unknown");
        assert_eq!(e.flag, "iso_field");
        assert_eq!(s.iso_field, "speed");
    }
}
