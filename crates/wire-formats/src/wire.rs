//! A minimal little-endian binary writer and reader for persisted state
//! (streaming sessions), and the error of bytes that are not a valid
//! encoding. Every read is bounds-checked: a truncated or corrupt buffer
//! gives an error, never a panic.

use std::error::Error;

/// Why stored bytes could not be read back.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The bytes are not an encoding this crate writes (truncated, an
    /// unknown tag or version, trailing bytes).
    #[error("corrupt encoded state: {0}")]
    Corrupt(String),
    /// The bytes decode, but to values the numerical core rejects (a
    /// configuration, a covariance that is not positive definite, an index
    /// out of range): that rejection, made with [`invalid`].
    #[error("encoded state is not valid: {0}")]
    Invalid(#[source] Box<dyn Error + Send + Sync>),
}

/// The error of bytes that decode to values their type rejects (the
/// numerical core's error, kept as the source).
pub fn invalid(e: impl Into<Box<dyn Error + Send + Sync>>) -> FormatError {
    FormatError::Invalid(e.into())
}

/// Appends values to a byte buffer.
#[derive(Debug, Default)]
pub struct Writer {
    /// The bytes written so far.
    pub buf: Vec<u8>,
}

impl Writer {
    /// One byte.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// A boolean as one byte, 0 or 1.
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    /// A u32, little-endian.
    pub fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A u64, little-endian.
    pub fn u64(&mut self, v: u64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A length or an index, stored as u64.
    pub fn usize(&mut self, v: usize) {
        self.u64(v as u64);
    }

    /// An f64, its bits little-endian.
    pub fn f64(&mut self, v: f64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A length, then the values.
    pub fn f64s(&mut self, v: &[f64]) {
        self.usize(v.len());
        self.f64_run(v);
    }

    /// The values alone, without a length (the reader knows how many).
    pub fn f64_run(&mut self, v: &[f64]) {
        self.buf.reserve(8 * v.len());
        for &x in v {
            self.f64(x);
        }
    }

    /// A length, then the UTF-8 bytes.
    pub fn str(&mut self, v: &str) {
        self.usize(v.len());
        self.buf.extend_from_slice(v.as_bytes());
    }

    /// A length, then the bytes.
    pub fn bytes(&mut self, v: &[u8]) {
        self.usize(v.len());
        self.buf.extend_from_slice(v);
    }

    /// `None` as 0, `Some` as 1 followed by the value.
    pub fn opt<T>(&mut self, v: Option<T>, f: impl FnOnce(&mut Self, T)) {
        match v {
            None => self.u8(0),
            Some(x) => {
                self.u8(1);
                f(self, x);
            }
        }
    }
}

/// Reads values back in the order they were written.
#[derive(Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
}

/// The error of a buffer that is not a valid encoding, saying why.
pub fn corrupt(reason: &str) -> FormatError {
    FormatError::Corrupt(reason.to_string())
}

impl<'a> Reader<'a> {
    /// A reader at the start of `buf`.
    pub fn new(buf: &'a [u8]) -> Self {
        Self { buf }
    }

    /// Whether every byte has been read.
    pub fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], FormatError> {
        if self.buf.len() < n {
            return Err(corrupt("truncated"));
        }
        let (head, tail) = self.buf.split_at(n);
        self.buf = tail;
        Ok(head)
    }

    /// One byte.
    pub fn u8(&mut self) -> Result<u8, FormatError> {
        Ok(self.take(1)?[0])
    }

    /// A boolean; a byte other than 0 or 1 is an error.
    pub fn bool(&mut self) -> Result<bool, FormatError> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(corrupt("bad boolean")),
        }
    }

    /// A little-endian u32.
    pub fn u32(&mut self) -> Result<u32, FormatError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes(b.try_into().expect("4 bytes")))
    }

    /// A little-endian u64.
    pub fn u64(&mut self) -> Result<u64, FormatError> {
        let b = self.take(8)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }

    /// A length or index; lengths are bounded by the bytes left so that a
    /// corrupt length cannot make the caller allocate without bound.
    pub fn usize(&mut self) -> Result<usize, FormatError> {
        usize::try_from(self.u64()?).map_err(|_| corrupt("index out of range"))
    }

    /// A count of items each at least `item_bytes` long.
    pub fn len(&mut self, item_bytes: usize) -> Result<usize, FormatError> {
        let n = self.usize()?;
        if n.saturating_mul(item_bytes.max(1)) > self.buf.len() {
            return Err(corrupt("length beyond the buffer"));
        }
        Ok(n)
    }

    /// An f64 from its little-endian bits.
    pub fn f64(&mut self) -> Result<f64, FormatError> {
        let b = self.take(8)?;
        Ok(f64::from_le_bytes(b.try_into().expect("8 bytes")))
    }

    /// `K` values [`Writer::f64_run`] wrote.
    pub fn f64_run<const K: usize>(&mut self) -> Result<[f64; K], FormatError> {
        let mut out = [0.0; K];
        for v in &mut out {
            *v = self.f64()?;
        }
        Ok(out)
    }

    /// What [`Writer::f64s`] wrote.
    pub fn f64s(&mut self) -> Result<Vec<f64>, FormatError> {
        let n = self.len(8)?;
        (0..n).map(|_| self.f64()).collect()
    }

    /// What [`Writer::str`] wrote; bad UTF-8 is an error.
    pub fn str(&mut self) -> Result<String, FormatError> {
        let n = self.len(1)?;
        String::from_utf8(self.take(n)?.to_vec()).map_err(|_| corrupt("bad UTF-8"))
    }

    /// What [`Writer::bytes`] wrote.
    pub fn bytes(&mut self) -> Result<Vec<u8>, FormatError> {
        let n = self.len(1)?;
        Ok(self.take(n)?.to_vec())
    }

    /// What [`Writer::opt`] wrote, the value read by `f`.
    pub fn opt<T>(
        &mut self,
        f: impl FnOnce(&mut Self) -> Result<T, FormatError>,
    ) -> Result<Option<T>, FormatError> {
        match self.u8()? {
            0 => Ok(None),
            1 => f(self).map(Some),
            _ => Err(corrupt("bad option tag")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_and_truncation_is_an_error() {
        let mut w = Writer::default();
        w.u8(7);
        w.bool(true);
        w.u32(0xdead_beef);
        w.u64(u64::MAX);
        w.f64(-1.5e-300);
        w.f64s(&[1.0, f64::INFINITY]);
        w.str("n1/τ");
        w.opt(Some(3u32), |w, v| w.u32(v));
        w.opt(None::<u32>, |w, v| w.u32(v));
        let mut r = Reader::new(&w.buf);
        assert_eq!(r.u8().unwrap(), 7);
        assert!(r.bool().unwrap());
        assert_eq!(r.u32().unwrap(), 0xdead_beef);
        assert_eq!(r.u64().unwrap(), u64::MAX);
        assert_eq!(r.f64().unwrap(), -1.5e-300);
        assert_eq!(r.f64s().unwrap(), vec![1.0, f64::INFINITY]);
        assert_eq!(r.str().unwrap(), "n1/τ");
        assert_eq!(r.opt(|r| r.u32()).unwrap(), Some(3));
        assert_eq!(r.opt(|r| r.u32()).unwrap(), None);
        assert!(r.is_empty());
        for cut in 0..w.buf.len() {
            let mut r = Reader::new(&w.buf[..cut]);
            let all = (|| {
                r.u8()?;
                r.bool()?;
                r.u32()?;
                r.u64()?;
                r.f64()?;
                r.f64s()?;
                r.str()?;
                r.opt(|r| r.u32())?;
                r.opt(|r| r.u32())
            })();
            assert!(all.is_err(), "cut at {cut} must fail");
        }
    }

    #[test]
    fn a_huge_length_is_rejected_without_allocating() {
        let mut w = Writer::default();
        w.u64(u64::MAX / 2);
        assert!(Reader::new(&w.buf).f64s().is_err());
    }
}
