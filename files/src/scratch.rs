//! Values kept in a scratch file and read through a shared mapping: how a bake holds field
//! values larger than it wants resident. The kernel pages them in as they are read and
//! writes back what is changed; [`ScratchValues::release`] lets a pass over them drop the
//! pages behind itself, so that a front-to-back pass over gigabytes keeps only what it is
//! working on resident. The file is the caller's (normally unnamed, from
//! `tempfile::tempfile_in`, so it is gone once closed, also after a crash).

use std::fs::File;
use std::marker::PhantomData;
use std::ops::Range;

/// Makes `file` `bytes` long with its blocks allocated, so that values written through a
/// mapping of it never need a block the disk has no room for: such a write cannot fail
/// with an error, it kills the process (`SIGBUS`). A full disk is an error here instead.
/// Where the file system cannot allocate ahead (`EOPNOTSUPP`), the file is only sized.
pub fn reserve(file: &File, bytes: u64) -> std::io::Result<()> {
    match rustix::fs::fallocate(file, rustix::fs::FallocateFlags::empty(), 0, bytes) {
        Ok(()) => Ok(()),
        Err(rustix::io::Errno::OPNOTSUPP) => file.set_len(bytes),
        Err(e) => Err(e.into()),
    }
}

/// `len` values of `T` (plain data: `f32` for fields, a cell's velocity for the cells) in a
/// scratch file, mapped shared and writable.
pub struct ScratchValues<T = f32> {
    map: memmap2::MmapMut,
    len: usize,
    kind: PhantomData<T>,
}

impl<T> std::fmt::Debug for ScratchValues<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScratchValues")
            .field("len", &self.len)
            .finish()
    }
}

impl<T: bytemuck::Pod> ScratchValues<T> {
    const SIZE: usize = std::mem::size_of::<T>();

    /// Maps the first `len` values of `file`, which must hold at least that many bytes.
    pub fn map(file: &File, len: usize) -> std::io::Result<ScratchValues<T>> {
        let bytes = len
            .checked_mul(Self::SIZE)
            .ok_or_else(|| std::io::Error::other("scratch values past the address space"))?;
        let have = file.metadata()?.len();
        if have < bytes as u64 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!("scratch file holds {have} bytes, {bytes} expected"),
            ));
        }
        if bytes == 0 {
            // A zero-length mapping is refused by the kernel: an anonymous empty one.
            return Ok(ScratchValues {
                map: memmap2::MmapMut::map_anon(1)?,
                len: 0,
                kind: PhantomData,
            });
        }
        Ok(ScratchValues {
            map: map_shared(file, bytes)?,
            len,
            kind: PhantomData,
        })
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn as_slice(&self) -> &[T] {
        // A mapping is page-aligned, so aligned for any plain value.
        bytemuck::cast_slice(&self.map[..self.len * Self::SIZE])
    }

    pub fn as_mut_slice(&mut self) -> &mut [T] {
        let bytes = self.len * Self::SIZE;
        bytemuck::cast_slice_mut(&mut self.map[..bytes])
    }

    /// Says that the values in `range` will not be used for a while: the pages wholly
    /// inside it leave this process's resident memory. What was written to them is kept
    /// (the mapping is shared: it is the file's, in the page cache until written back), and
    /// a later read of them faults them in again with the same values.
    pub fn release(&self, range: Range<usize>) {
        release_shared::<T>(&self.map, self.len, range);
    }

    /// Whether a fault reads ahead (it does unless turned off). A pass that writes values
    /// all over the mapping turns it off for its writes: with readahead each fault brings
    /// in, and maps, a large folio of the file, so between two releases of a window (a few
    /// MiB) such a pass mapped up to 170 MiB of a scratch file with a disk whose readahead
    /// is 8 MiB, and a 134 M-cell bake within `--memory 95M` peaked at 233 MiB (106 MiB
    /// without). Passes that read in order keep it: reading back a billion cells' values
    /// without it took a third longer.
    pub fn read_ahead(&self, on: bool) {
        let advice = match on {
            true => memmap2::Advice::Normal,
            false => memmap2::Advice::Random,
        };
        // Advice is a hint: a kernel that refuses it changes nothing but the peak.
        let _ = self.map.advise(advice);
    }
}

/// The first `bytes` of `file` (this process's own scratch file) mapped shared and
/// writable.
#[allow(unsafe_code)]
fn map_shared(file: &File, bytes: usize) -> std::io::Result<memmap2::MmapMut> {
    // SAFETY: `MmapMut::map_mut` is unsafe because another mapping or process may change or
    // truncate the file under us. The file is this process's own unnamed scratch file,
    // which nothing else can open, and it is not shrunk while mapped (a `ScratchVec` maps
    // it again after it grows, dropping the mapping before).
    unsafe { memmap2::MmapOptions::new().len(bytes).map_mut(file) }
}

/// Lets the pages of `map` (shared, of its file) wholly inside the values `range` of the
/// first `len` values of `T` go.
#[allow(unsafe_code)]
fn release_shared<T>(map: &memmap2::MmapMut, len: usize, range: Range<usize>) {
    let size = std::mem::size_of::<T>();
    let bytes = range.start.saturating_mul(size)..range.end.min(len).saturating_mul(size);
    if let Some(pages) = crate::input::whole_pages(bytes, len.saturating_mul(size)) {
        // SAFETY: `MADV_DONTNEED` discards private and anonymous pages' contents; this
        // mapping is shared and backed by its file, so the pages are only unmapped and
        // their contents (with every write made through the mapping) stay the file's.
        // Advice the kernel refuses changes nothing, so its error is ignored.
        let _ = unsafe {
            map.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, pages.start, pages.len())
        };
    }
}

/// A growable array of plain values in a scratch file, mapped shared: what a bake builds
/// when the array may be larger than its memory budget allows (the regions and KD-tree of
/// a billion cells are a gigabyte). Values are written through the mapping, and every
/// `window` bytes written the pages behind are let go (their contents stay the file's), so
/// building it keeps about a window resident; a read faults pages in again, and
/// [`ScratchVec::release`] lets a pass over it drop them. The file grows by doubling, its
/// blocks allocated first ([`reserve`]: a full disk is an error, not `SIGBUS`).
pub struct ScratchVec<T> {
    file: File,
    map: Option<memmap2::MmapMut>,
    cap: usize,
    len: usize,
    window: usize,
    since_release: usize,
    kind: PhantomData<T>,
}

impl<T> std::fmt::Debug for ScratchVec<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScratchVec")
            .field("len", &self.len)
            .field("cap", &self.cap)
            .finish()
    }
}

impl<T: bytemuck::Pod> ScratchVec<T> {
    const SIZE: usize = std::mem::size_of::<T>();

    /// An empty array kept in `file` (the caller's scratch file, which nothing else
    /// writes), letting go of its pages every `window` bytes written.
    pub fn new(file: File, window: usize) -> ScratchVec<T> {
        ScratchVec {
            file,
            map: None,
            cap: 0,
            len: 0,
            window: window.max(1),
            since_release: 0,
            kind: PhantomData,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn as_slice(&self) -> &[T] {
        match &self.map {
            // A mapping is page-aligned, so aligned for any plain value.
            Some(m) => bytemuck::cast_slice(&m[..self.len * Self::SIZE]),
            None => &[],
        }
    }

    pub fn as_mut_slice(&mut self) -> &mut [T] {
        let bytes = self.len * Self::SIZE;
        match &mut self.map {
            Some(m) => bytemuck::cast_slice_mut(&mut m[..bytes]),
            None => &mut [],
        }
    }

    /// Room for `additional` more values: the file made larger (doubling) and mapped
    /// again, which also lets every page go.
    pub fn reserve(&mut self, additional: usize) -> std::io::Result<()> {
        let need = self
            .len
            .checked_add(additional)
            .ok_or_else(|| std::io::Error::other("scratch array past the address space"))?;
        if need <= self.cap {
            return Ok(());
        }
        let least = (1usize << 20) / Self::SIZE.max(1);
        let cap = need.max(self.cap.saturating_mul(2)).max(least);
        let bytes = cap
            .checked_mul(Self::SIZE)
            .ok_or_else(|| std::io::Error::other("scratch array past the address space"))?;
        reserve(&self.file, bytes as u64)?;
        self.map = None;
        self.map = Some(map_shared(&self.file, bytes)?);
        self.cap = cap;
        self.since_release = 0;
        Ok(())
    }

    pub fn push(&mut self, value: T) -> std::io::Result<()> {
        self.extend_from_slice(std::slice::from_ref(&value))
    }

    pub fn extend_from_slice(&mut self, values: &[T]) -> std::io::Result<()> {
        self.reserve(values.len())?;
        let (at, n) = (self.len, values.len());
        self.len += n;
        self.as_mut_slice()[at..at + n].copy_from_slice(values);
        self.wrote(n);
        Ok(())
    }

    /// `n` values long: cut, or filled with `value`.
    pub fn resize(&mut self, n: usize, value: T) -> std::io::Result<()> {
        if n <= self.len {
            self.truncate(n);
            return Ok(());
        }
        self.reserve(n - self.len)?;
        // A window at a time, letting the pages go behind (a fill of millions of values
        // would otherwise make them all resident at once).
        let step = (self.window / Self::SIZE.max(1)).max(1);
        while self.len < n {
            let (at, end) = (self.len, (self.len + step).min(n));
            self.len = end;
            self.as_mut_slice()[at..end].fill(value);
            self.wrote(end - at);
        }
        Ok(())
    }

    pub fn truncate(&mut self, n: usize) {
        self.len = self.len.min(n);
    }

    fn wrote(&mut self, values: usize) {
        self.since_release = self.since_release.saturating_add(values * Self::SIZE);
        if self.since_release >= self.window {
            self.release(0..self.len);
            self.since_release = 0;
        }
    }

    /// Lets the pages wholly inside the values `range` go, as [`ScratchValues::release`].
    pub fn release(&self, range: Range<usize>) {
        if let Some(map) = &self.map {
            release_shared::<T>(map, self.len, range);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// Values written through the mapping and released are read back unchanged, from the
    /// mapping and from the file; a file shorter than asked is refused.
    #[test]
    fn released_values_keep_what_was_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut file = tempfile::tempfile_in(dir.path()).expect("scratch");
        let n = 300_000;
        let values: Vec<f32> = (0..n).map(|i| i as f32 * 0.25).collect();
        file.write_all(bytemuck::cast_slice(&values))
            .expect("write");
        let mut mapped = ScratchValues::<f32>::map(&file, n).expect("map");
        assert_eq!(mapped.as_slice(), &values[..]);
        mapped.as_mut_slice()[123_456] = -1.0;
        mapped.release(0..n);
        let mut expected = values.clone();
        expected[123_456] = -1.0;
        assert_eq!(mapped.as_slice(), &expected[..]);
        drop(mapped);
        let again = ScratchValues::<f32>::map(&file, n).expect("map again");
        assert_eq!(again.as_slice(), &expected[..]);
        assert!(ScratchValues::<f32>::map(&file, n + 1).is_err());
        let empty = ScratchValues::<f32>::map(&file, 0).expect("empty");
        assert!(empty.is_empty() && empty.as_slice().is_empty());
    }

    /// The kernel's flags of the mapping holding `addr` (`VmFlags` of /proc/self/smaps).
    #[cfg(target_os = "linux")]
    fn vm_flags(addr: usize) -> Vec<String> {
        let smaps = std::fs::read_to_string("/proc/self/smaps").expect("smaps");
        let mut inside = false;
        for line in smaps.lines() {
            let first = line.split_whitespace().next().unwrap_or("");
            if let Some((lo, hi)) = first.split_once('-') {
                if let (Ok(lo), Ok(hi)) =
                    (usize::from_str_radix(lo, 16), usize::from_str_radix(hi, 16))
                {
                    inside = (lo..hi).contains(&addr);
                    continue;
                }
            }
            if let Some(flags) = line.strip_prefix("VmFlags:").filter(|_| inside) {
                return flags.split_whitespace().map(String::from).collect();
            }
        }
        panic!("no mapping holds {addr:#x}");
    }

    /// Scratch values read ahead unless turned off (`rr`, random reads, is the kernel's
    /// flag for off), and on again.
    #[cfg(target_os = "linux")]
    #[test]
    fn readahead_is_turned_off_and_on() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = tempfile::tempfile_in(dir.path()).expect("scratch");
        file.set_len(1 << 20).expect("size");
        let values = ScratchValues::<f32>::map(&file, 1 << 18).expect("map");
        let random = || {
            let flags = vm_flags(values.as_slice().as_ptr() as usize);
            flags.iter().any(|f| f == "rr")
        };
        assert!(!random());
        values.read_ahead(false);
        assert!(random());
        values.read_ahead(true);
        assert!(!random());
    }

    /// A scratch array reads back what was pushed, extended, resized, cut and changed
    /// through its slice, across growths and the releases behind its writes.
    #[test]
    fn a_scratch_array_keeps_what_was_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = tempfile::tempfile_in(dir.path()).expect("scratch");
        let mut a = ScratchVec::<[u32; 3]>::new(file, 4096);
        let mut b: Vec<[u32; 3]> = Vec::new();
        assert!(a.is_empty() && a.as_slice().is_empty());
        for i in 0..300_000u32 {
            let v = [i, i.wrapping_mul(7), !i];
            a.push(v).expect("push");
            b.push(v);
            if i % 50_000 == 7 {
                a.truncate(a.len() - 3);
                b.truncate(b.len() - 3);
                let more = [[1, 2, 3], [4, 5, 6]];
                a.extend_from_slice(&more).expect("extend");
                b.extend_from_slice(&more);
                let k = b.len() / 2;
                a.as_mut_slice()[k] = [i; 3];
                b[k] = [i; 3];
            }
        }
        a.resize(b.len() + 1000, [9; 3]).expect("resize");
        b.resize(b.len() + 1000, [9; 3]);
        assert_eq!(a.len(), b.len());
        assert!(a.as_slice() == &b[..]);
        a.release(0..a.len());
        assert!(a.as_slice() == &b[..]);
        a.resize(10, [0; 3]).expect("cut");
        assert_eq!(a.as_slice(), &b[..10]);
    }

    /// Values wider than a byte count the file in their own size: a velocity per value.
    /// A reserved file reads as zeros.
    #[test]
    fn vectors_are_mapped_in_their_own_size() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = tempfile::tempfile_in(dir.path()).expect("scratch");
        let n = 5000;
        reserve(&file, (n * 12) as u64).expect("reserve");
        assert_eq!(file.metadata().expect("metadata").len(), (n * 12) as u64);
        let mut mapped = ScratchValues::<[f32; 3]>::map(&file, n).expect("map");
        assert_eq!(mapped.len(), n);
        assert!(mapped.as_slice().iter().all(|v| *v == [0.0; 3]));
        mapped.as_mut_slice()[n - 1] = [1.0, -2.0, 3.5];
        mapped.release(0..n);
        assert_eq!(mapped.as_slice()[n - 1], [1.0, -2.0, 3.5]);
        assert!(ScratchValues::<[f32; 3]>::map(&file, n + 1).is_err());
    }
}
