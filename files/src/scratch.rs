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
    #[allow(unsafe_code)]
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
        // SAFETY: `MmapMut::map_mut` is unsafe because another mapping or process may change
        // or truncate the file under us. The file is this process's own unnamed scratch
        // file, which nothing else can open, and it is not resized while mapped.
        let map = unsafe { memmap2::MmapOptions::new().len(bytes).map_mut(file)? };
        Ok(ScratchValues {
            map,
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
    #[allow(unsafe_code)]
    pub fn release(&self, range: Range<usize>) {
        let size = Self::SIZE;
        let bytes = range.start.saturating_mul(size)..range.end.min(self.len).saturating_mul(size);
        if let Some(pages) = crate::input::whole_pages(bytes, self.len * size) {
            // SAFETY: `MADV_DONTNEED` discards private and anonymous pages' contents; this
            // mapping is shared and backed by its file, so the pages are only unmapped and
            // their contents (with every write made through the mapping) stay the file's.
            // Advice the kernel refuses changes nothing, so its error is ignored.
            let _ = unsafe {
                self.map.unchecked_advise_range(
                    memmap2::UncheckedAdvice::DontNeed,
                    pages.start,
                    pages.len(),
                )
            };
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
