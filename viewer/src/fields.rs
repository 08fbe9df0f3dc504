//! Fields by name: the one lookup of a field name in a list of fields, and the one error
//! for a name that is not there.
//!
//! A field is named in three places: a command-line flag (`--iso-field`, `--colour-field`,
//! `probe --field`), a view state (`iso_field`, `colormap.field`, from a file or the
//! window) and the window's field boxes. All of them look the name up here, so an unknown
//! name is refused the same way, listing the fields there are.

use format::sequence::FieldRange;

/// A field name that names no field of the data.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}", self.message())]
pub struct UnknownField {
    /// Where the name was given: a flag (`--iso-field`), a view-state key
    /// (`colormap.field`), or empty when it was asked for directly.
    pub flag: &'static str,
    pub name: String,
    /// The fields there are, in the data's order.
    pub known: Vec<String>,
}

impl UnknownField {
    /// The same error, for a name given as `flag` (a flag or a view-state key).
    pub fn named_by(self, flag: &'static str) -> UnknownField {
        UnknownField { flag, ..self }
    }

    /// A flag's name is checked against the data given on the command line (a file or a
    /// sequence): "no field named". A view state's or a direct lookup is checked against
    /// one opened file: "not in the file".
    fn message(&self) -> String {
        let known = self.known.join(", ");
        let name = &self.name;
        match self.flag {
            "" => format!("field {name:?} is not in the file (fields: {known})"),
            flag if flag.starts_with("--") => {
                format!("{flag}: no field named {name:?} (fields: {known})")
            }
            key => format!("{key}: field {name:?} is not in the file (fields: {known})"),
        }
    }
}

/// Index and range of the field called `name` in `fields`.
pub(crate) fn find<'f>(
    fields: &'f [FieldRange],
    name: &str,
) -> Result<(usize, &'f FieldRange), UnknownField> {
    fields
        .iter()
        .enumerate()
        .find(|(_, f)| f.name == name)
        .ok_or_else(|| UnknownField {
            flag: "",
            name: name.to_string(),
            known: fields.iter().map(|f| f.name.clone()).collect(),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_name_lists_the_fields_in_the_form_of_where_it_was_given() {
        let fields = [("q", -1.0, 2.0), ("speed", 0.0, 1.0)].map(|(n, min, max)| FieldRange {
            name: n.into(),
            min,
            max,
        });
        let (i, f) = find(&fields, "speed").expect("known");
        assert_eq!((i, f.max), (1, 1.0));
        let e = find(&fields, "w").expect_err("unknown");
        assert_eq!(e.known, ["q", "speed"]);
        assert_eq!(
            e.to_string(),
            "field \"w\" is not in the file (fields: q, speed)"
        );
        assert_eq!(
            e.clone().named_by("colormap.field").to_string(),
            "colormap.field: field \"w\" is not in the file (fields: q, speed)"
        );
        assert_eq!(
            e.named_by("--iso-field").to_string(),
            "--iso-field: no field named \"w\" (fields: q, speed)"
        );
    }
}
