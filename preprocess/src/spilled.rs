//! Arrays of a bake's structure (the regions with their brick lists, the KD-tree, the
//! regions' value ranges) that stay in memory while small and move to a scratch file past
//! a size: at a billion cells they are about a gigabyte, which a `--memory` budget may not
//! hold. On disk they are built through a shared mapping that lets its pages go behind
//! the writes ([`files::scratch::ScratchVec`]); the stages that read them afterwards read
//! them as slices and let the pages go behind each batch ([`Store::release_all`]), and the
//! writer streams them into the archive ([`format::streamed::Structure`]). Where they are
//! kept changes nothing in the file.

use std::io::ErrorKind;
use std::path::PathBuf;
use std::sync::Arc;

use files::scratch::ScratchVec;

/// Where and past what size a [`Store`] moves to disk.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct SpillTo {
    /// The scratch files' directory.
    pub dir: PathBuf,
    /// Bytes an array may take in memory.
    pub above: usize,
    /// Bytes written to a store on disk before the pages behind are let go.
    pub window: usize,
}

/// An array in memory, or in a scratch file once larger than its [`SpillTo`] allows. A
/// write that fails on disk (a full disk) is remembered ([`Store::failed`]) and the array
/// takes no more values; its owner reports it.
pub(crate) struct Store<T> {
    data: Data<T>,
    to: Option<Arc<SpillTo>>,
    failed: Option<ErrorKind>,
}

enum Data<T> {
    Memory(Vec<T>),
    Disk(ScratchVec<T>),
}

impl<T: bytemuck::Pod> Default for Store<T> {
    fn default() -> Self {
        Store::new(None)
    }
}

impl<T: bytemuck::Pod + std::fmt::Debug> std::fmt::Debug for Store<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl<T: bytemuck::Pod + PartialEq> PartialEq for Store<T> {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl<T: bytemuck::Pod> std::ops::Deref for Store<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        self.as_slice()
    }
}

impl<T: bytemuck::Pod> std::ops::DerefMut for Store<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        match &mut self.data {
            Data::Memory(v) => v,
            Data::Disk(d) => d.as_mut_slice(),
        }
    }
}

impl<T: bytemuck::Pod> From<Vec<T>> for Store<T> {
    fn from(v: Vec<T>) -> Self {
        Store {
            data: Data::Memory(v),
            to: None,
            failed: None,
        }
    }
}

impl<T: bytemuck::Pod> Store<T> {
    /// An empty array, kept in memory unless `to` says where to move it.
    pub(crate) fn new(to: Option<Arc<SpillTo>>) -> Self {
        Store {
            data: Data::Memory(Vec::new()),
            to,
            failed: None,
        }
    }

    /// What a write on disk failed with, if one did.
    pub(crate) fn failed(&self) -> Option<ErrorKind> {
        self.failed
    }

    /// Marks the array as failed with `e` (a part it was to hold stopped short).
    pub(crate) fn fail(&mut self, e: ErrorKind) {
        self.failed.get_or_insert(e);
    }

    /// Whether the array is in a scratch file.
    pub(crate) fn on_disk(&self) -> bool {
        matches!(self.data, Data::Disk(_))
    }

    pub(crate) fn as_slice(&self) -> &[T] {
        match &self.data {
            Data::Memory(v) => v,
            Data::Disk(d) => d.as_slice(),
        }
    }

    pub(crate) fn push(&mut self, value: T) {
        self.extend_from_slice(std::slice::from_ref(&value));
    }

    pub(crate) fn extend_from_slice(&mut self, values: &[T]) {
        if self.failed.is_some() {
            return;
        }
        self.spill_if_larger_than(self.len().saturating_add(values.len()));
        if self.failed.is_some() {
            return;
        }
        match &mut self.data {
            Data::Memory(v) => v.extend_from_slice(values),
            Data::Disk(d) => {
                if let Err(e) = d.extend_from_slice(values) {
                    self.failed = Some(e.kind());
                }
            }
        }
    }

    /// Appends `values` as they come, a few thousand at a time.
    pub(crate) fn extend(&mut self, values: impl IntoIterator<Item = T>) {
        let mut buf = Vec::with_capacity(4096);
        for v in values {
            buf.push(v);
            if buf.len() == buf.capacity() {
                self.extend_from_slice(&buf);
                buf.clear();
            }
        }
        self.extend_from_slice(&buf);
    }

    pub(crate) fn truncate(&mut self, n: usize) {
        match &mut self.data {
            Data::Memory(v) => v.truncate(n),
            Data::Disk(d) => d.truncate(n),
        }
    }

    /// `n` values long, new ones `value`.
    pub(crate) fn resize(&mut self, n: usize, value: T) {
        if self.failed.is_some() {
            return;
        }
        self.spill_if_larger_than(n);
        if self.failed.is_some() {
            return;
        }
        match &mut self.data {
            Data::Memory(v) => v.resize(n, value),
            Data::Disk(d) => {
                if let Err(e) = d.resize(n, value) {
                    self.failed = Some(e.kind());
                }
            }
        }
    }

    /// Lets every page of an array on disk go (a pass over it calls this behind each
    /// batch); nothing for one in memory.
    pub(crate) fn release_all(&self) {
        if let Data::Disk(d) = &self.data {
            d.release(0..d.len());
        }
    }

    /// The values in one `Vec` (read from disk if they are there).
    pub(crate) fn into_vec(self) -> Vec<T> {
        match self.data {
            Data::Memory(v) => v,
            Data::Disk(d) => d.as_slice().to_vec(),
        }
    }

    /// Lets the pages of the values `range` go, for an array on disk.
    pub(crate) fn release(&self, range: std::ops::Range<usize>) {
        if let Data::Disk(d) = &self.data {
            d.release(range);
        }
    }

    /// Moves the array to disk, before it grows to `len` values, when that is more than
    /// it may take in memory (so it is never held whole in memory past that).
    fn spill_if_larger_than(&mut self, len: usize) {
        let (Some(to), Data::Memory(v)) = (&self.to, &mut self.data) else {
            return;
        };
        if len.saturating_mul(std::mem::size_of::<T>()) <= to.above {
            return;
        }
        let moved = tempfile::tempfile_in(&to.dir).and_then(|file| {
            let mut d = ScratchVec::new(file, to.window);
            d.extend_from_slice(v)?;
            Ok(d)
        });
        match moved {
            Ok(d) => self.data = Data::Disk(d),
            Err(e) => self.failed = Some(e.kind()),
        }
        if self.failed.is_some() {
            // Nothing more is stored (see `failed`): what the memory held goes.
            self.data = Data::Memory(Vec::new());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A store past its size moves to disk and holds the same values as one in memory,
    /// through pushes, cuts, resizes and writes through its slice.
    #[test]
    fn a_store_on_disk_holds_what_one_in_memory_holds() {
        let dir = tempfile::tempdir().expect("tempdir");
        let to = Arc::new(SpillTo {
            dir: dir.path().to_path_buf(),
            above: 1000,
            window: 1 << 16,
        });
        let mut disk = Store::<u32>::new(Some(to));
        let mut mem = Store::<u32>::new(None);
        for s in [&mut disk, &mut mem] {
            for i in 0..100_000u32 {
                s.push(i);
                if i % 10_000 == 3 {
                    s.truncate(s.len() - 2);
                    s.extend((0..5).map(|k| k * i));
                    let k = s.len() / 3;
                    s[k] = !i;
                }
            }
            s.resize(s.len() + 77, 5);
            s.release_all();
        }
        assert!(disk.on_disk() && !mem.on_disk());
        assert!(disk.failed().is_none());
        assert!(disk == mem);
        assert_eq!(disk.into_vec(), mem.into_vec());
    }

    /// A directory the scratch file cannot be made in is remembered as the failure, and
    /// the store takes no more values.
    #[test]
    fn a_store_that_cannot_move_to_disk_says_so() {
        let to = Arc::new(SpillTo {
            dir: PathBuf::from("/nonexistent/qbricks-scratch"),
            above: 16,
            window: 1 << 16,
        });
        let mut s = Store::<u64>::new(Some(to));
        for i in 0..10 {
            s.push(i);
        }
        assert!(s.failed().is_some());
        assert!(s.is_empty());
    }
}
