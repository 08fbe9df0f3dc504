//! The window's file dialogs and what each was opened for: the files each can open
//! (filters), the name a save proposes, the extension a saved file gets.

use std::path::{Path, PathBuf};

use eframe::egui;
use egui_file_dialog::FileDialog;

/// What a file dialog was opened for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DialogPurpose {
    OpenFile,
    SavePng,
    SaveState,
    LoadState,
    AddMesh,
}

impl DialogPurpose {
    const ALL: [DialogPurpose; 5] = [
        DialogPurpose::OpenFile,
        DialogPurpose::SavePng,
        DialogPurpose::SaveState,
        DialogPurpose::LoadState,
        DialogPurpose::AddMesh,
    ];

    /// The extension of the file a save writes (`None`: the dialog opens a file).
    fn save_extension(self) -> Option<&'static str> {
        match self {
            DialogPurpose::SavePng => Some("png"),
            DialogPurpose::SaveState => Some("json"),
            _ => None,
        }
    }

    /// The dialog for this purpose: a save dialog for the outputs, else a pick dialog
    /// whose first filter (the one it starts with) shows only what `open_any` opens.
    fn dialog(self) -> FileDialog {
        let d = FileDialog::new();
        let (name, extensions) = match self {
            DialogPurpose::OpenFile => (
                "qbricks files (.qbk, .json, .obj)",
                vec!["qbk", "json", "obj"],
            ),
            DialogPurpose::LoadState => ("view states (.json)", vec!["json"]),
            DialogPurpose::AddMesh => ("meshes (.obj)", vec!["obj"]),
            DialogPurpose::SavePng => return d.add_save_extension("PNG image", "png"),
            DialogPurpose::SaveState => return d.add_save_extension("view state", "json"),
        };
        let d = d
            .add_file_filter_extensions(name, extensions)
            .default_file_filter(name);
        if self == DialogPurpose::OpenFile {
            // Listed so they can be found: opening one says how to bake it.
            d.add_file_filter_extensions("OpenVDB, to bake first (.vdb)", vec!["vdb"])
        } else {
            d
        }
    }
}

/// `path`, with `.EXT` added unless it already ends in it (in any case): a name typed
/// without it, or with a dot of its own (`wake.t2`), still gets a file of its kind.
pub(crate) fn with_extension(path: &Path, ext: &str) -> PathBuf {
    let has = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case(ext));
    if has {
        path.to_path_buf()
    } else {
        let mut name = path.as_os_str().to_os_string();
        name.push(".");
        name.push(ext);
        PathBuf::from(name)
    }
}

/// The name a save proposes: the open file's name with the output's extension
/// (`wake_small.qbk` → `wake_small.png`), or `view.EXT` with no file open.
pub(crate) fn proposed_name(open: Option<&Path>, ext: &str) -> String {
    let stem = open
        .and_then(Path::file_stem)
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "view".to_string());
    format!("{stem}.{ext}")
}

/// The file dialogs of the window, one per purpose so that each keeps its own folder and
/// filter; at most one is open.
pub(crate) struct Dialogs {
    dialogs: Vec<(DialogPurpose, FileDialog)>,
    purpose: Option<DialogPurpose>,
}

impl Dialogs {
    pub(crate) fn new() -> Dialogs {
        Dialogs {
            dialogs: DialogPurpose::ALL
                .iter()
                .map(|&p| (p, p.dialog()))
                .collect(),
            purpose: None,
        }
    }

    fn get(&mut self, purpose: DialogPurpose) -> Option<&mut FileDialog> {
        self.dialogs
            .iter_mut()
            .find(|(p, _)| *p == purpose)
            .map(|(_, d)| d)
    }

    /// Opens the dialog for `purpose`; a save dialog proposes a name made from the
    /// `open` file's.
    pub(crate) fn open(&mut self, purpose: DialogPurpose, open: Option<&Path>) {
        self.purpose = Some(purpose);
        let Some(d) = self.get(purpose) else {
            return;
        };
        match purpose.save_extension() {
            Some(ext) => {
                d.config_mut().default_file_name = proposed_name(open, ext);
                d.save_file();
            }
            None => d.pick_file(),
        }
    }

    /// Draws the open dialog; the file picked in it this frame, with what it was for.
    pub(crate) fn update(&mut self, ctx: &egui::Context) -> Option<(DialogPurpose, PathBuf)> {
        let purpose = self.purpose?;
        let d = self.get(purpose)?;
        d.update(ctx);
        let path = d.take_picked()?;
        self.purpose = None;
        Some((purpose, path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saves_propose_the_open_files_name_and_get_their_extension() {
        let open = Path::new("/data/wake_small.qbk");
        assert_eq!(proposed_name(Some(open), "png"), "wake_small.png");
        assert_eq!(proposed_name(None, "json"), "view.json");
        assert_eq!(
            with_extension(Path::new("/t/shot"), "png"),
            Path::new("/t/shot.png")
        );
        assert_eq!(
            with_extension(Path::new("/t/a.png"), "png"),
            Path::new("/t/a.png")
        );
        assert_eq!(
            with_extension(Path::new("/t/a.PNG"), "png"),
            Path::new("/t/a.PNG")
        );
        assert_eq!(
            with_extension(Path::new("/t/v.2"), "json"),
            Path::new("/t/v.2.json")
        );
    }
}
