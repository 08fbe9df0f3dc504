//! A bounds-checked little-endian reader over the file's bytes. Every length read from the
//! file goes through [`Cursor::take`] before anything is allocated from it.

use super::error::{ErrorKind, RawError, RawResult};

#[derive(Debug, Clone)]
pub(crate) struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(data: &'a [u8], pos: usize) -> Self {
        Cursor { data, pos }
    }

    pub(crate) fn pos(&self) -> usize {
        self.pos
    }

    pub(crate) fn left(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    pub(crate) fn truncated(&self, what: &'static str, expected: String) -> RawError {
        RawError::new(
            self.pos,
            what,
            ErrorKind::Truncated {
                expected,
                left: self.left() as u64,
            },
        )
    }

    /// `n` bytes, or an error saying `expected` (e.g. "512 values") was not there.
    pub(crate) fn take_as(
        &mut self,
        n: usize,
        what: &'static str,
        expected: impl FnOnce() -> String,
    ) -> RawResult<&'a [u8]> {
        if n > self.left() {
            return Err(self.truncated(what, expected()));
        }
        let out = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    pub(crate) fn take(&mut self, n: usize, what: &'static str) -> RawResult<&'a [u8]> {
        self.take_as(n, what, || format!("{n} bytes"))
    }

    pub(crate) fn skip(&mut self, n: usize, what: &'static str) -> RawResult<()> {
        self.take(n, what).map(|_| ())
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> RawResult<[u8; N]> {
        let bytes = self.take(N, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        Ok(out)
    }

    pub(crate) fn u8(&mut self, what: &'static str) -> RawResult<u8> {
        Ok(self.array::<1>(what)?[0])
    }

    pub(crate) fn u32(&mut self, what: &'static str) -> RawResult<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn i32(&mut self, what: &'static str) -> RawResult<i32> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn i64(&mut self, what: &'static str) -> RawResult<i64> {
        Ok(i64::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn f64(&mut self, what: &'static str) -> RawResult<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    pub(crate) fn vec3i(&mut self, what: &'static str) -> RawResult<[i32; 3]> {
        Ok([self.i32(what)?, self.i32(what)?, self.i32(what)?])
    }

    pub(crate) fn vec3d(&mut self, what: &'static str) -> RawResult<[f64; 3]> {
        Ok([self.f64(what)?, self.f64(what)?, self.f64(what)?])
    }

    /// OpenVDB string: u32 length, then that many bytes (not NUL-terminated).
    pub(crate) fn bytes_with_len(&mut self, what: &'static str) -> RawResult<&'a [u8]> {
        let start = self.pos;
        let len = self.u32(what)? as usize;
        if len > self.left() {
            let err = self.truncated(what, format!("a {len}-byte string"));
            return Err(RawError {
                offset: start as u64,
                ..err
            });
        }
        self.take(len, what)
    }

    pub(crate) fn string(&mut self, what: &'static str) -> RawResult<String> {
        Ok(String::from_utf8_lossy(self.bytes_with_len(what)?).into_owned())
    }

    /// A node mask of `bits` bits (a multiple of 64), as little-endian words.
    pub(crate) fn mask(&mut self, bits: usize, what: &'static str) -> RawResult<Vec<u64>> {
        let bytes = self.take(bits / 8, what)?;
        Ok(bytes
            .chunks_exact(8)
            .map(|c| {
                let mut a = [0u8; 8];
                a.copy_from_slice(c);
                u64::from_le_bytes(a)
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_little_endian_and_refuses_overruns() {
        let data = [1u8, 0, 0, 0, 0xff, 0xff, 0xff, 0xff, 9];
        let mut c = Cursor::new(&data, 0);
        assert_eq!(c.u32("a").unwrap(), 1);
        assert_eq!(c.i32("b").unwrap(), -1);
        let err = c.u32("c").unwrap_err();
        assert_eq!(err.offset, 8);
        assert!(matches!(err.kind, ErrorKind::Truncated { left: 1, .. }));
    }

    #[test]
    fn string_length_is_checked_before_use() {
        let data = [0xff, 0xff, 0xff, 0x7f, b'a'];
        let mut c = Cursor::new(&data, 0);
        assert!(c.string("name").is_err());
    }
}
