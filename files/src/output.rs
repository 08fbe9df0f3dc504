//! Writing output files, for every output of both programs: `.qbk`, VDB, PNG, view state,
//! manifests, plots, screenshots.
//!
//! [`write_atomic`] has the body write into a temporary file and puts it in place only
//! once it is complete. Where it goes depends on what the output path names:
//!
//! * a regular file, or nothing yet: the temporary file is made next to it
//!   (`.NAME.XXXXXX.tmp`, on the same file system), fsynced and renamed over it, so a
//!   reader sees the old complete file or the new complete file, never a partial one;
//! * a symlink: the same, at the file the link points to (followed to its end, even when
//!   that file does not exist yet). The link stays a link; replacing it with a regular
//!   file would cut whatever it connected;
//! * a device, a FIFO, or the process's own standard output or error (`/dev/stdout`,
//!   `/proc/self/fd/1`, a link to either, or the file stdout is redirected to): written
//!   into, never replaced, once the whole output has been produced (a failed run still
//!   writes nothing there). Renaming would replace the device node itself with a regular
//!   file, which as root silently breaks `/dev/null`; a regular file behind stdout is
//!   appended to, so `>>` keeps what was there;
//! * a directory (also through a link): refused.
//!
//! On any error the temporary file is removed; while it exists the [`crate::signals`]
//! handler removes it on SIGINT, SIGTERM or SIGHUP.
//!
//! [`QuietStdout`] is the other half of "no lost output": a closed stdout (`… | head -1`)
//! must not abort a run before its output file is written.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::limits::LimitError;
use crate::signals;
use std::fmt::Display;

/// Set once a write to [`QuietStdout`] found the reader gone.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);

/// Most symlinks followed from one output path (as the kernel's `MAXSYMLINKS`).
const MAX_LINKS: usize = 40;

/// A registered temporary file: removed from disk and from the registry when dropped,
/// unless it was renamed into place.
struct TempFile {
    path: PathBuf,
    file: File,
    keep: bool,
}

impl TempFile {
    fn create(dir: &Path, name: &str) -> io::Result<TempFile> {
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
        let mut live = signals::registry_with_cleanup();
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
        let mut live = signals::registry();
        std::fs::rename(&self.path, target)?;
        signals::unregister(&mut live, &self.path);
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
            let mut live = signals::registry();
            let _ = std::fs::remove_file(&self.path);
            signals::unregister(&mut live, &self.path);
        }
    }
}

/// Runs `body` on a fresh temporary file for `path`, and puts it in place (see the module
/// docs); returns what `body` returned. On any error, including errors of `body`, the
/// temporary file is removed and `path` is untouched.
///
/// `body` gets a plain `File` and may seek in it (the `.qbk` writer fills its header in
/// last), whatever the target is.
pub fn write_atomic<T, E: From<io::Error>>(
    path: &Path,
    body: impl FnOnce(&mut File) -> Result<T, E>,
) -> Result<T, E> {
    let mut pending = Pending::create(path)?;
    let value = body(pending.file())?;
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
        p.file().write_all(bytes).map_err(named)?;
        pending.push((path, p));
    }
    for (path, p) in pending {
        p.commit().map_err(|e| (path.to_path_buf(), e))?;
    }
    Ok(())
}

/// Where an output goes, decided before anything is written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// A regular file or a name that does not exist yet (the output path, or the end of
    /// its symlinks): replaced by a rename from its directory.
    Replace(PathBuf),
    /// A device, a FIFO, or a file behind the process's stdout or stderr: written into
    /// (appended to, for a regular file).
    Into { path: PathBuf, append: bool },
}

impl Target {
    /// Decides where an output named `path` goes (see the module docs). Fails for a
    /// directory, a socket, and a symlink loop.
    pub fn of(path: &Path) -> io::Result<Target> {
        let end = follow_links(path)?;
        let through_proc = end.starts_with("/proc") || end.starts_with("/dev/fd");
        match std::fs::metadata(&end) {
            Ok(m) if m.is_dir() => Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                "is a directory",
            )),
            Ok(m) if crate::input::Kind::of(&m) == crate::input::Kind::Socket => Err(
                io::Error::new(io::ErrorKind::InvalidInput, "is a socket, not a file"),
            ),
            Ok(m) if !m.is_file() => Ok(Target::Into {
                path: end,
                append: false,
            }),
            Ok(m) if through_proc || is_standard_stream(&m) => Ok(Target::Into {
                path: end,
                append: true,
            }),
            Ok(_) => Ok(Target::Replace(end)),
            Err(e) if e.kind() == io::ErrorKind::NotFound && !through_proc => {
                Ok(Target::Replace(end))
            }
            Err(e) => Err(e),
        }
    }

    /// Whether the output is written into an existing stream rather than put in place
    /// as a file of its own.
    pub fn is_stream(&self) -> bool {
        matches!(self, Target::Into { .. })
    }

    /// The directory the temporary file is made in, and the name it is made from.
    fn staging(&self) -> (PathBuf, String) {
        let (dir, name) = match self {
            Target::Replace(end) => (
                match end.parent() {
                    Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                    _ => PathBuf::from("."),
                },
                end.file_name(),
            ),
            // Not next to the target: `/dev` or `/proc/self/fd` is no place for it.
            Target::Into { path: end, .. } => (std::env::temp_dir(), end.file_name()),
        };
        let name = name
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".to_string());
        (dir, name)
    }
}

/// Refuses to start an output of up to `need` bytes for `what` (`the VDB file`) at `path`
/// when the file system its temporary file goes to (see [`write_atomic`]) has less room
/// for it: a long write is better refused at once than failed at the end. Where the free
/// space cannot be read, the write is let through (it still fails cleanly, leaving
/// nothing behind, if the disk fills).
pub fn check_space(what: impl Display, path: &Path, need: u64) -> Result<(), LimitError> {
    let Ok(target) = Target::of(path) else {
        // Said by the write itself, with its own message.
        return Ok(());
    };
    let (dir, _) = target.staging();
    check_space_in(what, &dir, need)
}

/// Refuses to start writing up to `need` bytes for `what` into directory `dir` when its
/// file system has less room (as [`check_space`]).
pub fn check_space_in(what: impl Display, dir: &Path, need: u64) -> Result<(), LimitError> {
    let Ok(st) = rustix::fs::statvfs(dir) else {
        return Ok(());
    };
    let free = st.f_bavail.saturating_mul(st.f_frsize);
    if need <= free {
        return Ok(());
    }
    Err(LimitError::Disk {
        what: what.to_string(),
        need,
        free,
        dir: dir.to_path_buf(),
    })
}

/// The directory [`write_atomic`] makes `path`'s temporary file in: beside it, or the
/// system's temporary directory for a device or a descriptor. Where a writer of `path` may
/// keep scratch files that the output itself would have room for.
pub fn staging_dir(path: &Path) -> PathBuf {
    match Target::of(path) {
        Ok(target) => target.staging().0,
        Err(_) => std::env::temp_dir(),
    }
}

/// The path a chain of symlinks in the last component of `path` ends at (`path` itself
/// when it is not a link), also when that end does not exist. Stops at `/proc` and
/// `/dev/fd`, whose links (`/proc/self/fd/1` → `pipe:[…]`) are not paths but the kernel
/// opens them as the file they stand for.
fn follow_links(path: &Path) -> io::Result<PathBuf> {
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        if p.starts_with("/proc") || p.starts_with("/dev/fd") {
            return Ok(p);
        }
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let to = std::fs::read_link(&p)?;
                p = match p.parent() {
                    Some(dir) if to.is_relative() => dir.join(to),
                    _ => to,
                };
                p = lexically_normal(&p);
            }
            _ => return Ok(p),
        }
    }
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("more than {MAX_LINKS} symbolic links (a loop?)"),
    ))
}

/// `p` with `.` components removed (`..` kept: it may cross a symlinked directory).
fn lexically_normal(p: &Path) -> PathBuf {
    p.components()
        .filter(|c| !matches!(c, Component::CurDir))
        .collect()
}

/// Whether `meta` is the file behind this process's standard output or error.
fn is_standard_stream(meta: &std::fs::Metadata) -> bool {
    #[cfg(unix)]
    {
        use std::os::fd::AsFd;
        use std::os::unix::fs::MetadataExt;
        // `st_dev`/`st_ino` are u64 here but narrower on some platforms.
        #[allow(clippy::unnecessary_cast)]
        let same = |st: rustix::io::Result<rustix::fs::Stat>| {
            st.is_ok_and(|st| st.st_dev as u64 == meta.dev() && st.st_ino as u64 == meta.ino())
        };
        same(rustix::fs::fstat(io::stdout().as_fd()))
            || same(rustix::fs::fstat(io::stderr().as_fd()))
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        false
    }
}

/// An output being written: its temporary file and where it goes.
struct Pending {
    tmp: TempFile,
    target: Target,
}

impl Pending {
    fn create(path: &Path) -> io::Result<Pending> {
        if path.file_name().is_none() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "expected a file name",
            ));
        }
        let target = Target::of(path)?;
        let (dir, name) = target.staging();
        Ok(Pending {
            tmp: TempFile::create(&dir, &name)?,
            target,
        })
    }

    fn file(&mut self) -> &mut File {
        &mut self.tmp.file
    }

    /// Puts the finished temporary file in place (renamed, or copied into a stream; the
    /// temporary file is removed then when it is dropped).
    fn commit(mut self) -> io::Result<()> {
        match &self.target {
            Target::Into { path, append } => {
                use std::io::Seek;
                let f = &mut self.tmp.file;
                f.flush()?;
                f.seek(io::SeekFrom::Start(0))?;
                let mut target = std::fs::OpenOptions::new()
                    .write(true)
                    .append(*append)
                    .open(path)?;
                io::copy(f, &mut target)?;
                target.flush()
            }
            Target::Replace(end) => {
                self.tmp.file.sync_all()?;
                self.tmp.rename_to(end)?;
                // Make the rename itself durable. Some file systems refuse to fsync a
                // directory; the data is already safe then, so this is best effort.
                let dir = match end.parent() {
                    Some(p) if !p.as_os_str().is_empty() => p,
                    _ => Path::new("."),
                };
                if let Ok(d) = File::open(dir) {
                    let _ = d.sync_all();
                }
                Ok(())
            }
        }
    }
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
    /// An output is refused when its file system has less room than it needs, and the
    /// error names the directory its temporary file would go to; a stream's temporary
    /// file goes to the temp dir.
    #[test]
    fn space_is_checked_where_the_temporary_file_goes() {
        use super::{check_space, LimitError};
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("out.vdb");
        let free = {
            let st = rustix::fs::statvfs(dir.path()).expect("statvfs");
            st.f_bavail * st.f_frsize
        };
        check_space("a small file", &out, 1 << 10).expect("room for a kilobyte");
        match check_space("a huge file", &out, free + (1 << 30)) {
            Err(e @ LimitError::Disk { .. }) => {
                let text = e.to_string();
                assert!(text.starts_with("a huge file needs up to "), "{text}");
                assert!(
                    text.ends_with(&format!("free in {}", dir.path().display())),
                    "{text}"
                );
            }
            other => panic!("expected a disk error, got {other:?}"),
        }
        let LimitError::Disk { dir: tmp, .. } =
            check_space("into a device", std::path::Path::new("/dev/null"), u64::MAX)
                .expect_err("no file system has 16 EiB free")
        else {
            panic!("expected a disk error");
        };
        assert_eq!(tmp, std::env::temp_dir());
    }

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
        crate::signals::live()
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

    /// A symlink stays a link; the file it points to gets the output, atomically.
    #[cfg(unix)]
    #[test]
    fn a_symlink_is_written_through_not_replaced() {
        let dir = tempfile::tempdir().expect("tempdir");
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).expect("mkdir");
        let real = sub.join("real.png");
        std::fs::write(&real, b"old").expect("write");
        let link = dir.path().join("link.png");
        std::os::unix::fs::symlink("sub/real.png", &link).expect("symlink");
        write_atomic(&link, |f| f.write_all(b"new")).expect("write");
        assert!(std::fs::symlink_metadata(&link)
            .expect("meta")
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&real).expect("read"), b"new");
        // A dangling link: the file it names is created, the link kept.
        let dangling = dir.path().join("dangling.png");
        std::os::unix::fs::symlink("sub/later.png", &dangling).expect("symlink");
        write_atomic(&dangling, |f| f.write_all(b"made")).expect("write");
        assert_eq!(std::fs::read(sub.join("later.png")).expect("read"), b"made");
        assert!(std::fs::symlink_metadata(&dangling)
            .expect("meta")
            .file_type()
            .is_symlink());
        assert_eq!(
            leftovers(&sub),
            vec!["later.png".to_owned(), "real.png".to_owned()]
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_link_to_a_directory_or_a_loop_is_refused_and_kept() {
        let dir = tempfile::tempdir().expect("tempdir");
        let link = dir.path().join("d.png");
        std::os::unix::fs::symlink(".", &link).expect("symlink");
        let e = write_atomic(&link, |f| f.write_all(b"x")).expect_err("directory");
        assert_eq!(e.kind(), io::ErrorKind::IsADirectory);
        let a = dir.path().join("a");
        let b = dir.path().join("b");
        std::os::unix::fs::symlink("b", &a).expect("symlink");
        std::os::unix::fs::symlink("a", &b).expect("symlink");
        let e = write_atomic(&a, |f| f.write_all(b"x")).expect_err("loop");
        assert!(e.to_string().contains("symbolic links"), "{e}");
        assert_eq!(
            leftovers(dir.path()),
            vec!["a".to_owned(), "b".to_owned(), "d.png".to_owned()]
        );
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn standard_streams_and_devices_are_written_into() {
        assert!(Target::of(Path::new("/dev/null"))
            .expect("target")
            .is_stream());
        assert!(Target::of(Path::new("/dev/stdout"))
            .expect("target")
            .is_stream());
        assert!(Target::of(Path::new("/proc/self/fd/2"))
            .expect("target")
            .is_stream());
        let dir = tempfile::tempdir().expect("tempdir");
        let link = dir.path().join("out.png");
        std::os::unix::fs::symlink("/dev/null", &link).expect("symlink");
        assert!(Target::of(&link).expect("target").is_stream());
        write_atomic(&link, |f| f.write_all(b"discarded")).expect("write");
        assert!(std::fs::symlink_metadata(&link)
            .expect("meta")
            .file_type()
            .is_symlink());
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_written_into() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("fifo");
        rustix::fs::mkfifoat(rustix::fs::CWD, &p, rustix::fs::Mode::from_raw_mode(0o600))
            .expect("mkfifo");
        let reader_path = p.clone();
        let reader = std::thread::spawn(move || std::fs::read(reader_path).expect("read"));
        write_atomic(&p, |f| f.write_all(b"through the pipe")).expect("write");
        assert_eq!(reader.join().expect("reader"), b"through the pipe");
        assert_eq!(leftovers(dir.path()), vec!["fifo".to_owned()]);
    }

    #[test]
    fn same_file_sees_through_dots_and_missing_targets() {
        let same_file =
            |a: &Path, b: &Path| crate::guard::FileKey::of(a).same(&crate::guard::FileKey::of(b));
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
