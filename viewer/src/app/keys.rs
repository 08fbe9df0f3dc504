//! Every key and mouse binding of the window, in one table each. The key handling reads
//! [`KEYS`], the help overlay and the menus print it, so what the help says is what the
//! keys do. The mouse table is what the image's navigation (`canvas`) does; the help
//! overlay and the panel's hint line print it.

use eframe::egui::{self, Key, KeyboardShortcut, Modifiers};

/// What a key asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum KeyAction {
    FrameSurface,
    FrameData,
    Undo,
    Redo,
    /// Show or hide the list of keys and mouse bindings.
    Help,
    /// Hide that list (only while it is shown).
    CloseHelp,
}

/// One key binding: the shortcut, what it does, and the words the help shows for it.
pub(crate) struct KeyBinding {
    pub shortcut: KeyboardShortcut,
    pub action: KeyAction,
    pub what: &'static str,
}

const fn key(modifiers: Modifiers, key: Key, action: KeyAction, what: &'static str) -> KeyBinding {
    KeyBinding {
        shortcut: KeyboardShortcut::new(modifiers, key),
        action,
        what,
    }
}

const CMD_SHIFT: Modifiers = Modifiers::COMMAND.plus(Modifiers::SHIFT);

/// The window's keys. Shortcuts with more modifiers come first: a shortcut matches a
/// press that has extra shift (so `?`, typed with shift, matches), and Ctrl+Shift+Z must
/// not be taken for Ctrl+Z.
pub(crate) const KEYS: &[KeyBinding] = &[
    key(
        CMD_SHIFT,
        Key::Z,
        KeyAction::Redo,
        "redo the view change undone",
    ),
    key(
        Modifiers::COMMAND,
        Key::Z,
        KeyAction::Undo,
        "undo the last view change",
    ),
    key(
        Modifiers::COMMAND,
        Key::Y,
        KeyAction::Redo,
        "redo (as Ctrl+Shift+Z)",
    ),
    key(
        Modifiers::NONE,
        Key::F,
        KeyAction::FrameSurface,
        "frame the iso surface (what the picture shows)",
    ),
    key(
        Modifiers::NONE,
        Key::Home,
        KeyAction::FrameData,
        "frame the whole data set",
    ),
    key(
        Modifiers::NONE,
        Key::F1,
        KeyAction::Help,
        "show or hide this list",
    ),
    key(
        Modifiers::NONE,
        Key::Questionmark,
        KeyAction::Help,
        "show or hide this list",
    ),
    key(
        Modifiers::NONE,
        Key::Escape,
        KeyAction::CloseHelp,
        "close this list",
    ),
];

/// The mouse on the image: gesture, the word for the panel's hint line, what it does.
pub(crate) const MOUSE: &[(&str, &str, &str)] = &[
    ("drag", "orbit", "orbit around the pivot"),
    ("right/middle or shift-drag", "pan", "pan"),
    ("wheel", "zoom", "zoom towards the cursor"),
    (
        "double-click",
        "pivot",
        "put the pivot on the surface (and show its values)",
    ),
];

/// The shortcuts of this frame's key presses, in table order; none while a text field
/// has the keyboard (Ctrl+Z there undoes typing, F types an F). `help_open`: whether
/// Escape has a list to close (otherwise it is left to others, such as the file dialog).
pub(crate) fn pressed(ctx: &egui::Context, help_open: bool) -> Vec<KeyAction> {
    if ctx.egui_wants_keyboard_input() {
        return Vec::new();
    }
    ctx.input_mut(|i| {
        KEYS.iter()
            .filter(|b| help_open || b.action != KeyAction::CloseHelp)
            .filter(|b| i.consume_shortcut(&b.shortcut))
            .map(|b| b.action)
            .collect()
    })
}

/// A shortcut as the platform writes it ("Ctrl+Shift+Z"); a key without modifiers by its
/// symbol (`?`, where egui would write "Questionmark").
pub(crate) fn shortcut_name(ctx: &egui::Context, shortcut: &KeyboardShortcut) -> String {
    if shortcut.modifiers.is_none() {
        shortcut.logical_key.symbol_or_name().to_string()
    } else {
        ctx.format_shortcut(shortcut)
    }
}

/// The keys of `action`, as [`shortcut_name`] writes them, joined.
pub(crate) fn shortcut_text(ctx: &egui::Context, action: KeyAction) -> String {
    KEYS.iter()
        .filter(|b| b.action == action)
        .map(|b| shortcut_name(ctx, &b.shortcut))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The mouse bindings on one line, for the panel.
pub(crate) fn mouse_hint() -> String {
    MOUSE
        .iter()
        .map(|(gesture, short, _)| format!("{gesture}: {short}"))
        .collect::<Vec<_>>()
        .join(" · ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shortcuts_with_more_modifiers_come_first() {
        // A binding must not be shadowed by an earlier one that matches the same press.
        for (i, late) in KEYS.iter().enumerate() {
            for early in &KEYS[..i] {
                let press = late.shortcut.modifiers;
                let shadows = early.shortcut.logical_key == late.shortcut.logical_key
                    && press.matches_logically(early.shortcut.modifiers);
                assert!(!shadows, "{:?} is shadowed", late.shortcut);
            }
        }
    }
}
