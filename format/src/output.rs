//! Writing output files, for every output of both programs: `.qbk`, VDB, PNG, view state.
//!
//! [`write_atomic`] writes into a temporary file next to the target (`.NAME.XXXXXX.tmp`, on
//! the same file system so the final rename is atomic), fsyncs it, then
//!
//! * renames it over the target when the target is a regular file or does not exist, so a
//!   reader sees the old complete file or the new complete file, never a partial one;
//! * copies it into the target when the target exists and is not a regular file
//!   (`/dev/null`, a FIFO, a terminal): renaming would replace the device node itself with
//!   a regular file, which as root silently breaks `/dev/null`. The copy starts only once
//!   the whole output has been produced, so a failed run still writes nothing there.
//!
//! On any error the temporary file is removed. While it exists its path is in a registry of
//! live temporary files; the first write installs a handler for SIGINT, SIGTERM and SIGHUP
//! that removes every registered file and then ends the process as the signal would have
//! (so the exit status still says "killed by SIGINT"). Without it, Ctrl-C in the middle of
//! a large write left a hidden temporary file behind on every run.
//!
//! [`QuietStdout`] is the other half of "no lost output": a closed stdout (`… | head -1`)
//! must not abort a run before its output file is written.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, Once};

/// Live temporary files, removed by the signal handler.
static LIVE_TEMPS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
static HANDLER: Once = Once::new();

/// Set once a write to [`QuietStdout`] found the reader gone.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);

/// Installs (once) the handler that removes live temporary files on SIGINT/SIGTERM/SIGHUP.
fn install_signal_cleanup() {
    HANDLER.call_once(|| {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
            // Without the handler a signal still ends the process; only the cleanup of
            // temporary files is lost. Nothing better to do than write without it.
            return;
        };
        let spawned = std::thread::Builder::new()
            .name("qbricks-signal-cleanup".into())
            .spawn(move || {
                if let Some(signal) = signals.forever().next() {
                    remove_live_temps();
                    let _ = signal_hook::low_level::emulate_default_handler(signal);
                    // A signal whose default is not to terminate cannot reach here (only
                    // terminating ones are registered); end the process anyway.
                    std::process::exit(128 + signal);
                }
            });
        drop(spawned);
    });
}

fn remove_live_temps() {
    let live = LIVE_TEMPS.lock().unwrap_or_else(|e| e.into_inner());
    for p in live.iter() {
        let _ = std::fs::remove_file(p);
    }
    // The lock is held until the process ends, so no new temporary file is registered (or
    // renamed into place) after the cleanup.
    std::mem::forget(live);
}

/// A registered temporary file: removed from disk and from the registry when dropped,
/// unless it was renamed into place.
struct TempFile {
    path: PathBuf,
    file: File,
    keep: bool,
}

impl TempFile {
    fn create(dir: &Path, name: &str) -> io::Result<TempFile> {
        install_signal_cleanup();
        let prefix = format!(".{name}.");
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".tmp");
        // Temporary files are private (0600) by default; the result is an ordinary output
        // file, so ask for 0666 and let the umask narrow it, as `File::create` would.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        // Register under the lock before the file exists, so a signal between creating
        // and registering cannot leave it behind.
        let mut live = LIVE_TEMPS.lock().unwrap_or_else(|e| e.into_inner());
        let (file, path) = builder
            .tempfile_in(dir)
            .map_err(without_temp_name)?
            .keep()
            .map_err(|e| e.error)?;
        live.push(path.clone());
        drop(live);
        Ok(TempFile {
            path,
            file,
            keep: false,
        })
    }

    /// Renames the temporary file to `target` (under the registry lock, so the signal
    /// handler cannot remove it half-way). The open handle is closed on drop; renaming an
    /// open file is fine on Unix.
    fn rename_to(mut self, target: &Path) -> io::Result<()> {
        let mut live = LIVE_TEMPS.lock().unwrap_or_else(|e| e.into_inner());
        std::fs::rename(&self.path, target)?;
        live.retain(|p| p != &self.path);
        self.keep = true;
        Ok(())
    }
}

/// The error of a failed temporary-file creation without tempfile's `at path
/// "<temporary name>"` suffix (the user named the target, not the temporary file).
fn without_temp_name(e: io::Error) -> io::Error {
    let msg = e.to_string();
    match msg.split_once(" at path ") {
        Some((cause, _)) => io::Error::new(e.kind(), cause.to_string()),
        None => e,
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !self.keep {
            let mut live = LIVE_TEMPS.lock().unwrap_or_else(|e| e.into_inner());
            let _ = std::fs::remove_file(&self.path);
            live.retain(|p| p != &self.path);
        }
    }
}

/// Runs `body` on a fresh temporary file next to `path`, fsyncs it and puts it in place
/// (see the module docs); returns what `body` returned. On any error, including errors
/// of `body`, the temporary file is removed and `path` is untouched.
///
/// `body` gets a plain `File` and may seek in it (the `.qbk` writer fills its header in
/// last), whatever the target is.
pub fn write_atomic<T, E: From<io::Error>>(
    path: &Path,
    body: impl FnOnce(&mut File) -> Result<T, E>,
) -> Result<T, E> {
    let mut pending = Pending::create(path)?;
    let value = body(&mut pending.tmp.file)?;
    pending.commit()?;
    Ok(value)
}

/// Writes several outputs all or nothing (as far as a file system allows): every output is
/// first written completely to its temporary file, and only when all of them succeeded are
/// they put in place, one after the other. A failure while writing any of them leaves every
/// target untouched. Errors name the output that failed.
pub fn write_all_atomic(outputs: &[(&Path, &[u8])]) -> Result<(), (PathBuf, io::Error)> {
    let mut pending = Vec::with_capacity(outputs.len());
    for (path, bytes) in outputs {
        let named = |e| (path.to_path_buf(), e);
        let mut p = Pending::create(path).map_err(named)?;
        p.tmp.file.write_all(bytes).map_err(named)?;
        pending.push(p);
    }
    for p in pending {
        let path = p.target.clone();
        p.commit().map_err(|e| (path, e))?;
    }
    Ok(())
}

/// An output being written: its temporary file and where it goes.
struct Pending {
    tmp: TempFile,
    target: PathBuf,
    dir: PathBuf,
    /// The target exists and is not a regular file (nor a directory, which the rename
    /// refuses with its own message): it is written into, not replaced.
    special: bool,
}

impl Pending {
    fn create(path: &Path) -> io::Result<Pending> {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let name = path
            .file_name()
            .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "expected a file name"))?
            .to_string_lossy()
            .into_owned();
        let special = std::fs::metadata(path)
            .map(|m| !m.is_file() && !m.is_dir())
            .unwrap_or(false);
        Ok(Pending {
            tmp: TempFile::create(dir, &name)?,
            target: path.to_path_buf(),
            dir: dir.to_path_buf(),
            special,
        })
    }

    /// Puts the finished temporary file in place (renamed, or copied into a special target).
    fn commit(mut self) -> io::Result<()> {
        if self.special {
            use std::io::Seek;
            let f = &mut self.tmp.file;
            f.flush()?;
            f.seek(io::SeekFrom::Start(0))?;
            let mut target = std::fs::OpenOptions::new().write(true).open(&self.target)?;
            io::copy(f, &mut target)?;
            return target.flush();
        }
        self.tmp.file.sync_all()?;
        self.tmp.rename_to(&self.target)?;
        // Make the rename itself durable. Some file systems refuse to fsync a directory;
        // the data is already safe then, so this is best effort.
        if let Ok(d) = File::open(&self.dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }
}

/// Whether `a` and `b` name the same file (or would, for a target that does not exist):
/// compared after resolving symlinks, `.` and `..`, and on Unix also by device and inode,
/// so hard links count too.
pub fn same_file(a: &Path, b: &Path) -> bool {
    if let (Some(ca), Some(cb)) = (canonical(a), canonical(b)) {
        if ca == cb {
            return true;
        }
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    false
}

/// Canonical form of `p`; for a path that does not exist yet, of its parent plus its name.
fn canonical(p: &Path) -> Option<PathBuf> {
    if let Ok(c) = p.canonicalize() {
        return Some(c);
    }
    let name = p.file_name()?;
    let parent = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    parent.canonicalize().ok().map(|d| d.join(name))
}

/// Standard output that treats a closed reader (EPIPE) as the end of interest, not as a
/// failure: the write reports success and later writes are skipped, so a run whose
/// report nobody reads still writes its output files and exits quietly with status 0.
/// Other errors (a full disk behind a redirect) are still errors.
pub struct QuietStdout(io::StdoutLock<'static>);

impl QuietStdout {
    pub fn new() -> Self {
        Self(io::stdout().lock())
    }

    fn quiet(&self, r: io::Result<()>) -> io::Result<()> {
        match r {
            Err(e) if e.kind() == io::ErrorKind::BrokenPipe => {
                STDOUT_CLOSED.store(true, Ordering::Relaxed);
                Ok(())
            }
            other => other,
        }
    }
}

impl Default for QuietStdout {
    fn default() -> Self {
        Self::new()
    }
}

impl Write for QuietStdout {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if STDOUT_CLOSED.load(Ordering::Relaxed) {
            return Ok(buf.len());
        }
        let r = self.0.write_all(buf);
        self.quiet(r).map(|()| buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        if STDOUT_CLOSED.load(Ordering::Relaxed) {
            return Ok(());
        }
        let r = self.0.flush();
        self.quiet(r)
    }
}

/// Whether an error, or any error in its `source` chain, is a vanished stdout reader
/// (`BrokenPipe`, also when wrapped in a JSON serialisation error). Output through
/// [`QuietStdout`] never fails that way; this catches every other path, so both programs
/// can end such a run quietly with status 0 instead of reporting a failure.
pub fn is_broken_pipe(err: &(dyn std::error::Error + 'static)) -> bool {
    let broken = Some(io::ErrorKind::BrokenPipe);
    std::iter::successors(Some(err), |e| e.source()).any(|e| {
        e.downcast_ref::<io::Error>().map(io::Error::kind) == broken
            || e.downcast_ref::<serde_json::Error>()
                .and_then(serde_json::Error::io_error_kind)
                == broken
    })
}

#[cfg(test)]
mod tests {
    #[derive(Debug, thiserror::Error)]
    #[error("writing the report")]
    struct Wrapped(#[source] std::io::Error);

    #[test]
    fn a_broken_pipe_is_found_anywhere_in_the_chain() {
        use std::io::{Error, ErrorKind};
        let pipe = || Error::new(ErrorKind::BrokenPipe, "reader gone");
        assert!(super::is_broken_pipe(&pipe()));
        assert!(super::is_broken_pipe(&Wrapped(pipe())));
        let json = serde_json::Error::io(pipe());
        assert!(super::is_broken_pipe(&json));
        assert!(!super::is_broken_pipe(&Wrapped(Error::new(
            ErrorKind::StorageFull,
            "disk full"
        ))));
        let syntax = serde_json::from_str::<u32>("x").expect_err("not a number");
        assert!(!super::is_broken_pipe(&syntax));
    }

    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .expect("read dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    fn live() -> Vec<PathBuf> {
        LIVE_TEMPS.lock().expect("registry").clone()
    }

    #[test]
    fn failing_body_leaves_no_file_and_no_registration() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.qbk");
        let r: io::Result<()> = write_atomic(&path, |f| {
            f.write_all(b"half a file")?;
            assert!(live().iter().any(|p| p.starts_with(dir.path())));
            Err(io::Error::other("disk full (simulated)"))
        });
        assert!(r.is_err());
        assert_eq!(leftovers(dir.path()), Vec::<String>::new());
        assert!(!live().iter().any(|p| p.starts_with(dir.path())));
    }

    #[test]
    fn failing_body_leaves_existing_output_intact() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.qbk");
        std::fs::write(&path, b"old complete file").expect("write");
        let r: io::Result<()> = write_atomic(&path, |f| {
            f.write_all(b"new partial")?;
            Err(io::Error::other("disk full (simulated)"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&path).expect("read"), b"old complete file");
        assert_eq!(leftovers(dir.path()), vec!["out.qbk".to_owned()]);
    }

    #[test]
    fn successful_body_replaces_file_and_unregisters() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.qbk");
        std::fs::write(&path, b"old").expect("write");
        let n = write_atomic(&path, |f| -> io::Result<u64> {
            f.write_all(b"new")?;
            Ok(3)
        })
        .expect("write");
        assert_eq!(n, 3);
        assert_eq!(std::fs::read(&path).expect("read"), b"new");
        assert_eq!(leftovers(dir.path()), vec!["out.qbk".to_owned()]);
        assert!(!live().iter().any(|p| p.starts_with(dir.path())));
    }

    #[test]
    fn all_or_nothing_leaves_every_target_when_one_fails() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.png");
        std::fs::write(&a, b"old a").expect("write");
        let bad = dir.path().join("no/such/dir/b.json");
        let e = write_all_atomic(&[(&a, b"new a"), (&bad, b"new b")]).expect_err("no dir");
        assert_eq!(e.0, bad);
        assert_eq!(std::fs::read(&a).expect("read"), b"old a");
        assert_eq!(leftovers(dir.path()), vec!["a.png".to_owned()]);
        let b = dir.path().join("b.json");
        write_all_atomic(&[(&a, b"new a"), (&b, b"new b")]).expect("both");
        assert_eq!(std::fs::read(&a).expect("read"), b"new a");
        assert_eq!(std::fs::read(&b).expect("read"), b"new b");
    }

    #[test]
    fn missing_directory_error_does_not_show_the_temporary_name() {
        let dir = tempfile::tempdir().expect("tempdir");
        let e = write_atomic(&dir.path().join("no/x.png"), |f| f.write_all(b"x"))
            .expect_err("no directory");
        assert_eq!(e.kind(), io::ErrorKind::NotFound);
        assert!(!e.to_string().contains(".tmp"), "{e}");
    }

    #[test]
    fn body_may_seek_back() {
        use std::io::Seek;
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.bin");
        write_atomic(&path, |f| -> io::Result<()> {
            f.write_all(b"..world")?;
            f.seek(io::SeekFrom::Start(0))?;
            f.write_all(b"hi")
        })
        .expect("write");
        assert_eq!(std::fs::read(&path).expect("read"), b"hiworld");
    }

    #[cfg(unix)]
    #[test]
    fn output_permissions_follow_the_umask_like_file_create() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("tempdir");
        let plain = dir.path().join("plain");
        File::create(&plain).expect("create");
        let path = dir.path().join("out.qbk");
        write_atomic(&path, |f| f.write_all(b"x")).expect("write");
        let mode = |p: &Path| std::fs::metadata(p).expect("meta").permissions().mode() & 0o777;
        assert_eq!(mode(&path), mode(&plain));
    }

    /// A device is written into, not replaced by a regular file (as root the rename would
    /// succeed and turn `/dev/null` into a file).
    #[cfg(target_os = "linux")]
    #[test]
    fn device_target_is_written_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        write_atomic(Path::new("/dev/null"), |f| f.write_all(b"discarded")).expect("write");
        let ft = std::fs::metadata("/dev/null").expect("meta").file_type();
        assert!(ft.is_char_device());
    }

    #[test]
    fn same_file_sees_through_dots_and_missing_targets() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.vdb");
        std::fs::write(&a, b"x").expect("write");
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).expect("mkdir");
        assert!(same_file(&a, &sub.join("..").join("a.vdb")));
        assert!(!same_file(&a, &dir.path().join("b.qbk")));
        assert!(same_file(
            &dir.path().join("new.qbk"),
            &sub.join("../new.qbk")
        ));
        #[cfg(unix)]
        {
            let hard = dir.path().join("hard.vdb");
            std::fs::hard_link(&a, &hard).expect("hard link");
            assert!(same_file(&a, &hard));
            let soft = dir.path().join("soft.vdb");
            std::os::unix::fs::symlink(&a, &soft).expect("symlink");
            assert!(same_file(&soft, &a));
        }
    }
}
