//! Serialises a [`BrickFile`] and writes it atomically.
//!
//! [`write`] streams the archive through [`files::output::write_atomic`] (temporary file
//! in the target directory, fsync, rename; removed on error or SIGINT/SIGTERM), hashing it
//! on the way, then writes the header in front. A `.qbk` at the target path is always
//! either the old complete file or the new complete file, never a partial one. Nothing of the size of the archive is held in memory: a 1 GB file
//! needs no 1 GB buffer.

use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::Path;

use rkyv::rancor;

use crate::error::{one_line, FormatError, FormatErrorKind};
use crate::header::{Header, FLAGS, FORMAT_VERSION, HEADER_LEN};
use crate::schema::BrickFile;
use crate::streamed::{Release, Streamed, Structure};

/// Bytes of a complete `.qbk` file (header + archive) for `file`.
pub fn to_bytes(file: &BrickFile) -> Result<Vec<u8>, FormatErrorKind> {
    let payload = rkyv::to_bytes::<rancor::Error>(file)
        .map_err(|e| FormatErrorKind::Serialize(one_line(e)))?;
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(&Header::for_payload(&payload).to_bytes());
    out.extend_from_slice(&payload);
    Ok(out)
}

/// Writes `file` to `path` atomically; returns the number of bytes written. Whether
/// `path` may be written at all (not over an input of the run) is the caller's check,
/// `files::guard`, done before the work that produced `file`.
pub fn write(path: &Path, file: &BrickFile) -> Result<u64, FormatError> {
    write_atomically(path, |out| stream_archive(out, |w| archive_into(w, file)))
}

/// As [`write`], with the values of field `f` taken from `values[f]` instead of from
/// `file` (whose fields' own values are ignored), and `release(f, range)` called on each
/// range of them once written: the same bytes as [`write`] of the file holding those
/// values, without ever holding them in one `Vec` (see [`crate::streamed`]).
pub fn write_streamed(
    path: &Path,
    file: &BrickFile,
    values: &[&[f32]],
    release: Release<'_>,
) -> Result<u64, FormatError> {
    write_streamed_with(path, file, values, release, None)
}

/// As [`write_streamed`], with the regions and KD-tree taken from `structure` too when it
/// is given (the file's own are then ignored): the same bytes as [`write`] of the file
/// holding them.
pub fn write_streamed_with(
    path: &Path,
    file: &BrickFile,
    values: &[&[f32]],
    release: Release<'_>,
    structure: Option<Structure<'_>>,
) -> Result<u64, FormatError> {
    let streamed = Streamed::new(file, values, release).ok_or_else(|| {
        FormatError::new(
            path,
            FormatErrorKind::Serialize(format!(
                "{} value arrays for {} fields",
                values.len(),
                file.fields.len()
            )),
        )
    })?;
    let streamed = streamed.with_structure(structure);
    write_atomically(path, |out| {
        stream_archive(out, |w| archive_into(w, &streamed))
    })
}

/// The archive of `file` written through `w`.
fn archive_into<W, T>(w: W, file: &T) -> Result<(), rancor::Error>
where
    W: Write,
    T: for<'a> rkyv::Serialize<
        rkyv::api::high::HighSerializer<
            rkyv::ser::writer::IoWriter<W>,
            rkyv::ser::allocator::ArenaHandle<'a>,
            rancor::Error,
        >,
    >,
{
    rkyv::api::high::to_bytes_in::<_, rancor::Error>(file, rkyv::ser::writer::IoWriter::new(w))
        .map(drop)
}

/// Serialises an archive (`serialize` writes it through the writer it is given) after a
/// placeholder header, then fills the header in.
fn stream_archive(
    out: &mut File,
    serialize: impl FnOnce(&mut dyn Write) -> Result<(), rancor::Error>,
) -> Result<u64, FormatErrorKind> {
    out.write_all(&[0u8; HEADER_LEN])?;
    let mut sink = HashingWriter {
        inner: BufWriter::with_capacity(1 << 20, &mut *out),
        hasher: crate::header::ChunkedChecksum::default(),
        len: 0,
        error: None,
    };
    let result = serialize(&mut sink);
    if let Some(e) = sink.error.take() {
        return Err(e.into());
    }
    result.map_err(|e| FormatErrorKind::Serialize(one_line(e)))?;
    sink.inner.flush()?;
    let header = Header {
        format_version: FORMAT_VERSION,
        flags: FLAGS,
        payload_len: sink.len,
        checksum: sink.hasher.clone().digest(),
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
    hasher: crate::header::ChunkedChecksum,
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

/// [`files::output::write_atomic`] with the path attached to errors.
pub(crate) fn write_atomically(
    path: &Path,
    body: impl FnOnce(&mut File) -> Result<u64, FormatErrorKind>,
) -> Result<u64, FormatError> {
    files::output::write_atomic(path, body).map_err(|kind| FormatError::new(path, kind))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The writer's errors name the target, and a failing body leaves the old file.
    #[test]
    fn failing_body_names_the_file_and_keeps_the_old_one() {
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
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("read dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("out.qbk")]);
    }
}
