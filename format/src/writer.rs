//! Serialises a [`BrickFile`] and writes it atomically.
//!
//! [`write`] streams the archive into a temporary file in the target directory (so the
//! final rename stays on one file system), hashing it on the way, then writes the header
//! in front, `fsync`s the file, renames it over the target and `fsync`s the directory
//! (best effort). Any failure before the rename deletes the temporary file, so a `.qbk`
//! at the target path is always either the old complete file or the new complete file,
//! never a partial one. Nothing of the size of the archive is held in memory: a 1 GB file
//! needs no 1 GB buffer.

use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use rkyv::rancor;

use crate::error::{one_line, FormatError, FormatErrorKind};
use crate::header::{Header, FLAGS, FORMAT_VERSION, HEADER_LEN};
use crate::schema::BrickFile;

/// Options for [`write_with`].
#[derive(Debug, Clone, Default)]
pub struct WriteOptions {
    /// Refuse to write when the target is this file (compared after resolving symlinks,
    /// `.`/`..`, and on Unix also by device and inode, so hard links count too).
    /// `qbricks-bake` passes its input here.
    pub forbid_overwrite_of: Option<PathBuf>,
}

/// Bytes of a complete `.qbk` file (header + archive) for `file`.
pub fn to_bytes(file: &BrickFile) -> Result<Vec<u8>, FormatErrorKind> {
    let payload = rkyv::to_bytes::<rancor::Error>(file)
        .map_err(|e| FormatErrorKind::Serialize(one_line(e)))?;
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(&Header::for_payload(&payload).to_bytes());
    out.extend_from_slice(&payload);
    Ok(out)
}

/// Writes `file` to `path` atomically; returns the number of bytes written.
pub fn write(path: &Path, file: &BrickFile) -> Result<u64, FormatError> {
    write_with(path, file, &WriteOptions::default())
}

/// [`write`] with options.
pub fn write_with(
    path: &Path,
    file: &BrickFile,
    options: &WriteOptions,
) -> Result<u64, FormatError> {
    if let Some(input) = &options.forbid_overwrite_of {
        if same_file(path, input) {
            return Err(FormatError::new(
                path,
                FormatErrorKind::OverwritesInput {
                    input: input.clone(),
                },
            ));
        }
    }
    write_atomically(path, |out| stream_archive(out, file))
}

/// Serialises `file` after a placeholder header, then fills the header in.
fn stream_archive(out: &mut File, file: &BrickFile) -> Result<u64, FormatErrorKind> {
    out.write_all(&[0u8; HEADER_LEN])?;
    let mut sink = HashingWriter {
        inner: BufWriter::with_capacity(1 << 20, &mut *out),
        hasher: xxhash_rust::xxh3::Xxh3::new(),
        len: 0,
        error: None,
    };
    let result = rkyv::api::high::to_bytes_in::<_, rancor::Error>(
        file,
        rkyv::ser::writer::IoWriter::new(&mut sink),
    )
    .map(drop);
    if let Some(e) = sink.error.take() {
        return Err(e.into());
    }
    result.map_err(|e| FormatErrorKind::Serialize(one_line(e)))?;
    sink.inner.flush()?;
    let header = Header {
        format_version: FORMAT_VERSION,
        flags: FLAGS,
        payload_len: sink.len,
        checksum: sink.hasher.digest(),
    };
    let len = sink.len;
    drop(sink);
    out.seek(SeekFrom::Start(0))?;
    out.write_all(&header.to_bytes())?;
    Ok(HEADER_LEN as u64 + len)
}

/// Writes through to `inner`, hashing and counting the bytes; keeps the first I/O error
/// so it reaches the caller as an I/O error rather than a serialisation message.
struct HashingWriter<W: Write> {
    inner: W,
    hasher: xxhash_rust::xxh3::Xxh3,
    len: u64,
    error: Option<io::Error>,
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self.inner.write(buf) {
            Ok(n) => {
                let written = buf.get(..n).unwrap_or(buf);
                self.hasher.update(written);
                self.len += n as u64;
                Ok(n)
            }
            Err(e) => {
                if self.error.is_none() && e.kind() != io::ErrorKind::Interrupted {
                    self.error = Some(io::Error::new(e.kind(), e.to_string()));
                }
                Err(e)
            }
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Runs `body` on a fresh temporary file next to `path`, then fsyncs it and renames it
/// to `path`. On any error the temporary file is removed and `path` is untouched.
pub(crate) fn write_atomically(
    path: &Path,
    body: impl FnOnce(&mut File) -> Result<u64, FormatErrorKind>,
) -> Result<u64, FormatError> {
    let err = |kind| FormatError::new(path, kind);
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".to_owned());
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
    let mut tmp = builder.tempfile_in(dir).map_err(|e| err(e.into()))?;
    let written = body(tmp.as_file_mut()).map_err(err)?;
    tmp.as_file().sync_all().map_err(|e| err(e.into()))?;
    tmp.persist(path).map_err(|e| err(e.error.into()))?;
    // Make the rename itself durable. Some file systems refuse to fsync a directory;
    // the data is already safe then, so this is best effort.
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(written)
}

/// Whether `a` and `b` name the same file (or would, for a target that does not exist).
fn same_file(a: &Path, b: &Path) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .expect("read dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn failing_body_leaves_no_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.qbk");
        let r = write_atomically(&path, |f| {
            f.write_all(b"half a file")?;
            Err(io::Error::other("disk full (simulated)").into())
        });
        assert!(r.is_err());
        assert_eq!(leftovers(dir.path()), Vec::<String>::new());
    }

    #[test]
    fn failing_body_leaves_existing_output_intact() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.qbk");
        std::fs::write(&path, b"old complete file").expect("write");
        let r = write_atomically(&path, |f| {
            f.write_all(b"new partial")?;
            Err(io::Error::other("disk full (simulated)").into())
        });
        let e = r.expect_err("must fail");
        assert!(e.to_string().contains("out.qbk"), "{e}");
        assert_eq!(std::fs::read(&path).expect("read"), b"old complete file");
        assert_eq!(leftovers(dir.path()), vec!["out.qbk".to_owned()]);
    }

    #[test]
    fn successful_body_replaces_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("out.qbk");
        std::fs::write(&path, b"old").expect("write");
        let n = write_atomically(&path, |f| {
            f.write_all(b"new")?;
            Ok(3)
        })
        .expect("write");
        assert_eq!(n, 3);
        assert_eq!(std::fs::read(&path).expect("read"), b"new");
        assert_eq!(leftovers(dir.path()), vec!["out.qbk".to_owned()]);
    }

    #[cfg(unix)]
    #[test]
    fn output_permissions_follow_the_umask_like_file_create() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("tempdir");
        let plain = dir.path().join("plain");
        File::create(&plain).expect("create");
        let path = dir.path().join("out.qbk");
        write_atomically(&path, |f| {
            f.write_all(b"x")?;
            Ok(1)
        })
        .expect("write");
        let mode = |p: &Path| std::fs::metadata(p).expect("meta").permissions().mode() & 0o777;
        assert_eq!(mode(&path), mode(&plain));
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
    }
}
