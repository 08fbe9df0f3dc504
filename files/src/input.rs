//! Opening inputs without blocking, and reading them whole with a bound on what gets
//! allocated.
//!
//! `File::open` on a FIFO that no program writes to blocks until one does, which may be
//! never: every input here is opened non-blocking ([`open`]), so the open returns at once
//! whatever the file is, and only then is the file's kind looked at. A FIFO is read like
//! any stream (its reads block while a writer is connected, as they should); one with no
//! writer reads as empty and is reported as such. A socket is refused with its kind.
//!
//! Both programs read some inputs whole (VDB files, point lists, view states, OBJ meshes).
//! `std::fs::read` trusts the file: a regular file's size becomes one allocation, and a
//! device or pipe (`/dev/zero`, a FIFO) is read until it ends, which may be never. Here a
//! regular file's size is checked against a limit before anything is read, anything else
//! is read in bounded steps and refused once it passes a (smaller) limit, and every
//! allocation is a fallible reservation, so an address-space limit (`ulimit -v`) becomes an
//! error message instead of an abort.

use std::fs::{File, Metadata};
use std::io::Read;
use std::path::{Path, PathBuf};

/// How much [`read_whole`] may read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest regular file, checked against its size before reading.
    pub file: u64,
    /// Largest input that is not a regular file (device, FIFO, socket), whose size is not
    /// known in advance: refused once this many bytes have been read.
    pub stream: u64,
    /// Whether `file` is the address space left to map the file ([`Limits::mapped`]),
    /// rather than what reading it whole may take: said so when a file is over it.
    pub address_space: bool,
}

/// Default cap for inputs that are not regular files: large enough for a piped sample file,
/// small enough that `/dev/zero` is refused within a second.
pub(crate) const STREAM_LIMIT: u64 = 1 << 30;

impl Limits {
    /// Limits for a file that is decoded in memory as a whole (a VDB file): a regular file
    /// may be as large as the machine's physical memory (no larger one could be decoded),
    /// anything else up to [`STREAM_LIMIT`].
    pub fn memory() -> Self {
        Self {
            file: crate::limits::physical_memory().unwrap_or(u64::MAX),
            stream: STREAM_LIMIT,
            address_space: false,
        }
    }

    /// Limits for a file that is mapped and read a part at a time (a VDB file a bake
    /// decodes a batch of leaves at a time): a regular file of any size the address space
    /// can map (its pages are read as they are used and let go after; `ulimit -v` bounds
    /// the mapping), anything else up to [`STREAM_LIMIT`].
    pub fn mapped() -> Self {
        Self {
            file: crate::limits::address_space_left().unwrap_or(u64::MAX),
            stream: STREAM_LIMIT,
            address_space: true,
        }
    }

    /// The same limit for regular files and streams (small text inputs).
    pub fn both(bytes: u64) -> Self {
        Self {
            file: bytes,
            stream: bytes,
            address_space: false,
        }
    }
}

/// A failed [`read_whole`]: the file and what went wrong.
#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct InputError {
    pub path: PathBuf,
    pub kind: InputErrorKind,
}

/// What went wrong reading an input, without the path.
#[derive(Debug, thiserror::Error)]
pub enum InputErrorKind {
    #[error("cannot read: {0}")]
    Io(#[from] std::io::Error),
    #[error("is a directory, not a file")]
    IsDirectory,
    #[error("file is {size} bytes, more than the limit of {limit} bytes for reading it whole")]
    TooLarge { size: u64, limit: u64 },
    #[error(
        "file is {size} bytes, more than the limit of {limit} bytes of address space left to \
         map it (ulimit -v)"
    )]
    TooLargeToMap { size: u64, limit: u64 },
    #[error(
        "is not a regular file and is longer than {limit} bytes, the limit for devices and \
         pipes; copy it to a regular file first"
    )]
    StreamTooLarge { limit: u64 },
    #[error("cannot allocate {bytes} bytes to read it")]
    OutOfMemory { bytes: u64 },
    #[error("is a {0}, not a file")]
    NotAFile(&'static str),
    #[error("is a FIFO (named pipe) and no program wrote to it")]
    EmptyFifo,
}

/// What an input is, when it is not a regular file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Regular,
    Directory,
    /// A character or block device (`/dev/zero`, a terminal): a stream.
    Device,
    /// A FIFO or an anonymous pipe (`/dev/stdin` under `… |`): a stream.
    Fifo,
    Socket,
}

impl Kind {
    pub fn of(meta: &Metadata) -> Kind {
        let t = meta.file_type();
        if t.is_file() {
            return Kind::Regular;
        }
        if t.is_dir() {
            return Kind::Directory;
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if t.is_fifo() {
                return Kind::Fifo;
            }
            if t.is_socket() {
                return Kind::Socket;
            }
        }
        Kind::Device
    }
}

/// Opens `path` for reading without blocking (see the module docs) and returns it with
/// its metadata and kind. Directories and sockets are refused here, with their kind; a
/// FIFO or device is returned in blocking mode, ready to be read as a stream.
pub fn open(path: &Path) -> Result<(File, Metadata, Kind), InputErrorKind> {
    // A socket cannot be opened at all (`ENXIO`, "No such device or address"): say what
    // it is instead.
    if let Ok(m) = std::fs::metadata(path) {
        if Kind::of(&m) == Kind::Socket {
            return Err(InputErrorKind::NotAFile("socket"));
        }
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    let kind = Kind::of(&meta);
    match kind {
        Kind::Directory => return Err(InputErrorKind::IsDirectory),
        Kind::Socket => return Err(InputErrorKind::NotAFile("socket")),
        _ => {}
    }
    // Reads of a stream should wait for its writer, as they would have without the flag.
    #[cfg(unix)]
    if kind != Kind::Regular {
        let flags = rustix::fs::fcntl_getfl(&file).map_err(std::io::Error::from)?;
        rustix::fs::fcntl_setfl(&file, flags - rustix::fs::OFlags::NONBLOCK)
            .map_err(std::io::Error::from)?;
    }
    Ok((file, meta, kind))
}

/// Reads all of `path` within `limits` (see the module docs).
pub fn read_whole(path: &Path, limits: Limits) -> Result<Vec<u8>, InputError> {
    read_whole_kind(path, limits).map_err(|kind| InputError {
        path: path.to_path_buf(),
        kind,
    })
}

fn read_whole_kind(path: &Path, limits: Limits) -> Result<Vec<u8>, InputErrorKind> {
    let (mut file, meta, kind) = open(path)?;
    if kind == Kind::Regular {
        let size = meta.len();
        if size > limits.file {
            return Err(InputErrorKind::TooLarge {
                size,
                limit: limits.file,
            });
        }
        let mut data = Vec::new();
        reserve(&mut data, size)?;
        // The file may grow while it is read: never read more than the limit (+1 to see it).
        (&mut file).take(limits.file + 1).read_to_end(&mut data)?;
        if data.len() as u64 > limits.file {
            return Err(InputErrorKind::TooLarge {
                size: data.len() as u64,
                limit: limits.file,
            });
        }
        return Ok(data);
    }
    let data = read_stream(&mut file, limits.stream)?;
    if data.is_empty() && kind == Kind::Fifo {
        return Err(InputErrorKind::EmptyFifo);
    }
    Ok(data)
}

/// Reads a source of unknown length in 1 MiB steps, each a fallible reservation.
fn read_stream(src: &mut impl Read, limit: u64) -> Result<Vec<u8>, InputErrorKind> {
    const STEP: usize = 1 << 20;
    let mut data: Vec<u8> = Vec::new();
    loop {
        if data.len() as u64 > limit {
            return Err(InputErrorKind::StreamTooLarge { limit });
        }
        let want = (limit + 1 - data.len() as u64).min(STEP as u64);
        reserve(&mut data, want)?;
        let n = src.by_ref().take(want).read_to_end(&mut data)?;
        if n == 0 {
            return Ok(data);
        }
    }
}

fn reserve(data: &mut Vec<u8>, extra: u64) -> Result<(), InputErrorKind> {
    let total = (data.len() as u64).saturating_add(extra);
    usize::try_from(extra)
        .ok()
        .and_then(|n| data.try_reserve_exact(n).ok())
        .ok_or(InputErrorKind::OutOfMemory { bytes: total })
}

/// An input's whole bytes: a regular file mapped read-only, anything else read into
/// memory ([`map_whole`]).
pub enum Whole {
    Mapped(memmap2::Mmap),
    Read(Vec<u8>),
}

impl Default for Whole {
    fn default() -> Self {
        Whole::Read(Vec::new())
    }
}

impl std::fmt::Debug for Whole {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let how = match self {
            Whole::Mapped(_) => "mapped",
            Whole::Read(_) => "read",
        };
        write!(f, "{} bytes, {how}", self.len())
    }
}

impl std::ops::Deref for Whole {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Whole::Mapped(map) => map,
            Whole::Read(data) => data,
        }
    }
}

impl Whole {
    /// Says that the bytes in `range` will not be read again: the mapped pages wholly
    /// inside it leave this process's resident memory. They stay in the page cache, and a
    /// later read of them reads the file again, so nothing is lost if they are read after
    /// all. A reader that decodes a large file front to back calls this behind itself, so
    /// that the file never sits in memory whole beside what it is decoded into. Bytes read
    /// into memory stay.
    pub fn release(&self, range: std::ops::Range<usize>) {
        let Whole::Mapped(map) = self else {
            return;
        };
        if let Some(pages) = whole_pages(range, map.len()) {
            release_pages(map, pages.start, pages.len());
        }
    }
}

/// The pages lying wholly inside the bytes `range` of a mapping of `len` bytes (`None`
/// when there is none): what a release may drop without touching bytes outside `range`.
pub(crate) fn whole_pages(
    range: std::ops::Range<usize>,
    len: usize,
) -> Option<std::ops::Range<usize>> {
    let page = rustix::param::page_size();
    let start = range.start.div_ceil(page) * page;
    let end = (range.end.min(len) / page) * page;
    (start < end).then_some(start..end)
}

/// Drops the pages `offset..offset + len` of a read-only map from the resident set.
#[allow(unsafe_code)]
fn release_pages(map: &memmap2::Mmap, offset: usize, len: usize) {
    // SAFETY: `MADV_DONTNEED` is unsafe in general because it discards the contents of
    // private or anonymous pages that were written; this map is read-only and backed by
    // its file, so the pages are only unmapped and a later read faults them in again from
    // the file, with the same bytes. Advice the kernel refuses changes nothing, so its
    // error is ignored.
    let _ = unsafe { map.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, offset, len) };
}

/// Maps `file` (a regular file) read-only.
///
/// The mapping shows the file's current contents, not a snapshot: bytes another process
/// overwrites are read as they are then, and reading a page past the end of a file
/// another process truncated raises `SIGBUS`, which kills the process (this cannot be
/// caught safely in Rust). Both programs accept that risk, as OpenVDB's own mapped reading
/// does: their writers never change a file in place (they write a new file and rename it),
/// and every byte read is bounds-checked and validated before it is trusted.
#[allow(unsafe_code)]
pub fn map_read_only(file: &File) -> std::io::Result<memmap2::Mmap> {
    // SAFETY: `Mmap::map` is unsafe because the mapped bytes may change under us if the
    // file is modified or truncated by another process, which breaks the immutability a
    // `&[u8]` promises: the documented risk above, accepted.
    unsafe { memmap2::Mmap::map(file) }
}

/// The whole of `path`: a regular file mapped read-only ([`map_read_only`]: its pages are
/// read as they are used, and can be let go once used, see [`Whole::release`]) within
/// `limits.file`, anything else read as [`read_whole`] reads it, within `limits.stream`.
pub fn map_whole(path: &Path, limits: Limits) -> Result<Whole, InputError> {
    let err = |kind| InputError {
        path: path.to_path_buf(),
        kind,
    };
    let (file, meta, kind) = open(path).map_err(err)?;
    if kind != Kind::Regular || meta.len() == 0 {
        drop(file);
        return read_whole(path, limits).map(Whole::Read);
    }
    // Mapped or read, a file is decoded into at least its own size.
    let size = meta.len();
    if size > limits.file {
        let limit = limits.file;
        return Err(err(if limits.address_space {
            InputErrorKind::TooLargeToMap { size, limit }
        } else {
            InputErrorKind::TooLarge { size, limit }
        }));
    }
    map_read_only(&file)
        .map(Whole::Mapped)
        .map_err(|e| err(e.into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file larger than the machine's memory (sparse: it takes no disk) is mapped under
    /// [`Limits::mapped`], and refused by its size under [`Limits::memory`].
    #[test]
    fn a_file_larger_than_memory_is_mapped_not_refused() {
        let Some(physical) = crate::limits::physical_memory() else {
            return;
        };
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("big");
        let f = File::create(&p).expect("create");
        if f.set_len(physical + (1 << 20)).is_err() {
            return; // a file system that cannot hold such a file
        }
        let whole = map_whole(&p, Limits::mapped()).expect("mapped");
        assert_eq!(whole.len() as u64, physical + (1 << 20));
        assert_eq!(whole[whole.len() - 1], 0);
        whole.release(0..whole.len());
        assert!(matches!(
            map_whole(&p, Limits::memory()).map_err(|e| e.kind),
            Err(InputErrorKind::TooLarge { .. })
        ));
    }

    #[test]
    fn regular_file_within_the_limit_is_read_whole() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("a");
        std::fs::write(&p, b"0123456789").expect("write");
        assert_eq!(
            read_whole(&p, Limits::both(10)).expect("read"),
            b"0123456789"
        );
    }

    #[test]
    fn regular_file_over_the_limit_is_refused_by_size() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("a");
        std::fs::write(&p, b"0123456789").expect("write");
        let e = read_whole(&p, Limits::both(9)).expect_err("too large");
        assert!(matches!(
            e.kind,
            InputErrorKind::TooLarge { size: 10, limit: 9 }
        ));
        assert!(e
            .to_string()
            .starts_with(&format!("{}: file is 10 bytes", p.display())));
    }

    #[test]
    fn directory_is_named_as_such() {
        let dir = tempfile::tempdir().expect("tempdir");
        let e = read_whole(dir.path(), Limits::both(100)).expect_err("dir");
        assert!(matches!(e.kind, InputErrorKind::IsDirectory), "{e}");
    }

    #[test]
    fn endless_stream_stops_at_the_limit() {
        let e = read_stream(&mut std::io::repeat(0), 3 << 20).expect_err("endless");
        assert!(matches!(e, InputErrorKind::StreamTooLarge { limit } if limit == 3 << 20));
        // A stream of exactly the limit is fine, one byte more is not.
        let ok = read_stream(&mut std::io::repeat(1).take(5), 5).expect("5 bytes");
        assert_eq!(ok, vec![1; 5]);
        assert!(read_stream(&mut std::io::repeat(1).take(6), 5).is_err());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn dev_zero_is_refused_quickly() {
        let e = read_whole(Path::new("/dev/zero"), Limits::both(1 << 20)).expect_err("endless");
        assert!(
            matches!(e.kind, InputErrorKind::StreamTooLarge { .. }),
            "{e}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_without_a_writer_is_reported_not_waited_for() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("fifo");
        rustix::fs::mkfifoat(rustix::fs::CWD, &p, rustix::fs::Mode::from_raw_mode(0o600))
            .expect("mkfifo");
        let e = read_whole(&p, Limits::both(1 << 20)).expect_err("no writer");
        assert!(matches!(e.kind, InputErrorKind::EmptyFifo), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_with_a_writer_is_read_whole() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("fifo");
        rustix::fs::mkfifoat(rustix::fs::CWD, &p, rustix::fs::Mode::from_raw_mode(0o600))
            .expect("mkfifo");
        // The writer opens read-write (which does not wait for a reader), fills the pipe
        // and closes a little later: the read gets the bytes, then the end of the stream.
        let (tx, rx) = std::sync::mpsc::channel();
        let writer_path = p.clone();
        let writer = std::thread::spawn(move || {
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(&writer_path)
                .expect("open read-write");
            f.write_all(b"0,0,0\n").expect("write");
            tx.send(()).expect("signal");
            std::thread::sleep(std::time::Duration::from_millis(200));
        });
        rx.recv().expect("written");
        let data = read_whole(&p, Limits::both(1 << 20)).expect("read");
        writer.join().expect("writer");
        assert_eq!(data, b"0,0,0\n");
    }
}
