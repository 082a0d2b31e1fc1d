//! Reading values from a PLY body, ASCII or binary, behind one interface ([`Values`]) so that
//! the element logic in `ply.rs` is written once.
//!
//! Errors here are plain messages; the caller adds where ([`Values::at`]) and in which element.

use super::header::Scalar;

/// A message saying what is wrong at the current position.
pub(super) type ReadResult<T> = Result<T, String>;

/// One encoding's reader over the body.
pub(super) trait Values {
    /// Starts the next entry of an element (ASCII: reads its line).
    fn begin(&mut self) -> ReadResult<()>;
    /// Reads one value of type `ty`; integers are exact (every PLY integer type fits in `f64`),
    /// `float` values are read as `f32` and widened, so nothing is rounded twice.
    fn value(&mut self, ty: Scalar) -> ReadResult<f64>;
    /// Skips `n` values of type `ty`.
    fn skip(&mut self, ty: Scalar, n: u64) -> ReadResult<()>;
    /// Ends the current entry (ASCII: its line must hold no more values).
    fn end(&mut self) -> ReadResult<()>;
    /// Skips `count` entries of `size` bytes each at once, if the encoding can (binary).
    fn skip_entries(&mut self, count: u64, size: u64) -> Option<ReadResult<()>>;
    /// Checks that nothing but (ASCII) whitespace follows the last element.
    fn finish(&mut self) -> ReadResult<()>;
    /// Where the last value read (or the failed read) is: `line N` or `byte N`.
    fn at(&self) -> String;
    /// Where the current entry starts.
    fn entry_at(&self) -> String;
    /// Bytes of the body, for capacity bounds.
    fn body_len(&self) -> usize;
}

/// A list's count as read, checked to be non-negative.
pub(super) fn list_count(values: &mut impl Values, ty: Scalar) -> ReadResult<u64> {
    let n = values.value(ty)?;
    if n < 0.0 {
        return Err(format!("negative list length {n}"));
    }
    Ok(n as u64)
}

/// A binary body; `BIG` selects big endian.
pub(super) struct Binary<'a, const BIG: bool> {
    data: &'a [u8],
    /// File offset of `data[0]`, for messages.
    base: usize,
    pos: usize,
    /// Start of the last read, and of the current entry.
    last: usize,
    entry: usize,
}

impl<'a, const BIG: bool> Binary<'a, BIG> {
    pub(super) fn new(data: &'a [u8], base: usize) -> Self {
        Binary { data, base, pos: 0, last: 0, entry: 0 }
    }

    fn take<const N: usize>(&mut self) -> ReadResult<[u8; N]> {
        self.last = self.pos;
        let bytes = self.data.get(self.pos..self.pos + N).ok_or_else(|| self.truncated(N as u64))?;
        self.pos += N;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        if !BIG {
            out.reverse();
        }
        Ok(out)
    }

    fn truncated(&self, needed: u64) -> String {
        format!("the file ends here ({needed} bytes needed, {} left; truncated?)", self.data.len() - self.pos)
    }

    fn advance(&mut self, bytes: Option<u64>) -> ReadResult<()> {
        self.last = self.pos;
        let left = (self.data.len() - self.pos) as u64;
        match bytes {
            Some(n) if n <= left => {
                self.pos += n as usize;
                Ok(())
            }
            Some(n) => Err(self.truncated(n)),
            None => Err(format!("size overflows ({left} bytes left; truncated?)")),
        }
    }
}

impl<const BIG: bool> Values for Binary<'_, BIG> {
    fn begin(&mut self) -> ReadResult<()> {
        self.entry = self.pos;
        Ok(())
    }

    fn value(&mut self, ty: Scalar) -> ReadResult<f64> {
        // `take` returns the bytes in big-endian order.
        Ok(match ty {
            Scalar::I8 => f64::from(self.take::<1>()?[0] as i8),
            Scalar::U8 => f64::from(self.take::<1>()?[0]),
            Scalar::I16 => f64::from(i16::from_be_bytes(self.take()?)),
            Scalar::U16 => f64::from(u16::from_be_bytes(self.take()?)),
            Scalar::I32 => f64::from(i32::from_be_bytes(self.take()?)),
            Scalar::U32 => f64::from(u32::from_be_bytes(self.take()?)),
            Scalar::F32 => f64::from(f32::from_be_bytes(self.take()?)),
            Scalar::F64 => f64::from_be_bytes(self.take()?),
        })
    }

    fn skip(&mut self, ty: Scalar, n: u64) -> ReadResult<()> {
        self.advance(n.checked_mul(ty.size() as u64))
    }

    fn end(&mut self) -> ReadResult<()> {
        Ok(())
    }

    fn skip_entries(&mut self, count: u64, size: u64) -> Option<ReadResult<()>> {
        self.entry = self.pos;
        Some(self.advance(count.checked_mul(size)))
    }

    fn finish(&mut self) -> ReadResult<()> {
        self.last = self.pos;
        match self.data.len() - self.pos {
            0 => Ok(()),
            left => Err(format!("{left} bytes after the last element")),
        }
    }

    fn at(&self) -> String {
        format!("byte {}", self.base + self.last)
    }

    fn entry_at(&self) -> String {
        format!("byte {}", self.base + self.entry)
    }

    fn body_len(&self) -> usize {
        self.data.len()
    }
}

/// An ASCII body: one entry per line (blank lines are skipped), values separated by spaces
/// or tabs.
pub(super) struct Ascii<'a> {
    rest: &'a [u8],
    len: usize,
    /// Line number of the current entry.
    line: usize,
    /// Values of the current line not read yet.
    words: std::slice::Split<'a, u8, fn(&u8) -> bool>,
}

fn is_separator(b: &u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\x0b' | b'\x0c')
}

impl<'a> Ascii<'a> {
    /// `data` starts on line `first_line`.
    pub(super) fn new(data: &'a [u8], first_line: usize) -> Self {
        let empty: &'a [u8] = &[];
        Ascii {
            rest: data,
            len: data.len(),
            line: first_line.saturating_sub(1),
            words: empty.split(is_separator as fn(&u8) -> bool),
        }
    }

    /// The next line, without its `\n`; `None` at the end of the body.
    fn next_line(&mut self) -> Option<&'a [u8]> {
        if self.rest.is_empty() {
            return None;
        }
        let end = self.rest.iter().position(|&b| b == b'\n').unwrap_or(self.rest.len());
        let line = &self.rest[..end];
        self.rest = self.rest.get(end + 1..).unwrap_or_default();
        self.line += 1;
        Some(line)
    }

    fn word(&mut self) -> ReadResult<&'a str> {
        let word = self.words.find(|w| !w.is_empty()).ok_or("fewer values than the header declares")?;
        std::str::from_utf8(word).map_err(|_| "a value that is not ASCII text".to_string())
    }
}

impl Values for Ascii<'_> {
    fn begin(&mut self) -> ReadResult<()> {
        loop {
            let Some(line) = self.next_line() else {
                self.line += 1;
                return Err("the file ends here (fewer entries than the header declares; truncated?)".into());
            };
            if !line.iter().all(is_separator) {
                self.words = line.split(is_separator as fn(&u8) -> bool);
                return Ok(());
            }
        }
    }

    fn value(&mut self, ty: Scalar) -> ReadResult<f64> {
        let word = self.word()?;
        let bad = || format!("{word:?} is not a valid {ty} value");
        if !ty.is_integer() {
            // f32 directly: parsing to f64 and rounding again could differ in the last bit.
            return match ty {
                Scalar::F32 => word.parse::<f32>().map(f64::from).map_err(|_| bad()),
                _ => word.parse::<f64>().map_err(|_| bad()),
            };
        }
        let v: i64 = word.parse().map_err(|_| bad())?;
        let (lo, hi) = match ty {
            Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
            Scalar::U8 => (0, u8::MAX.into()),
            Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
            Scalar::U16 => (0, u16::MAX.into()),
            Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
            _ => (0, u32::MAX.into()),
        };
        if !(lo..=hi).contains(&v) {
            return Err(bad());
        }
        Ok(v as f64)
    }

    fn skip(&mut self, _ty: Scalar, n: u64) -> ReadResult<()> {
        // Skipped values are not parsed; each must be there.
        for _ in 0..n {
            self.word()?;
        }
        Ok(())
    }

    fn end(&mut self) -> ReadResult<()> {
        match self.words.find(|w| !w.is_empty()) {
            None => Ok(()),
            Some(_) => Err("more values than the header declares".into()),
        }
    }

    fn skip_entries(&mut self, _count: u64, _size: u64) -> Option<ReadResult<()>> {
        None
    }

    fn finish(&mut self) -> ReadResult<()> {
        while let Some(line) = self.next_line() {
            if !line.iter().all(is_separator) {
                return Err("data after the last element".into());
            }
        }
        Ok(())
    }

    fn at(&self) -> String {
        format!("line {}", self.line)
    }

    fn entry_at(&self) -> String {
        self.at()
    }

    fn body_len(&self) -> usize {
        self.len
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binary_both_endians_and_truncation() {
        let mut le = Binary::<false>::new(&[1, 0, 0xff, 0, 0, 0x80, 0x3f], 10);
        assert_eq!(le.value(Scalar::I16), Ok(1.0));
        assert_eq!(le.value(Scalar::I8), Ok(-1.0));
        assert_eq!(le.value(Scalar::F32), Ok(1.0));
        assert!(le.value(Scalar::U8).unwrap_err().contains("ends here"));
        assert_eq!(le.at(), "byte 17");
        let mut be = Binary::<true>::new(&[0x3f, 0x80, 0, 0, 0xff, 0xff], 0);
        assert_eq!(be.value(Scalar::F32), Ok(1.0));
        assert_eq!(be.value(Scalar::U16), Ok(65535.0));
        assert_eq!(be.finish(), Ok(()));
        assert!(be.skip(Scalar::F64, u64::MAX).is_err());
    }

    #[test]
    fn ascii_lines_ranges_and_leftovers() {
        let mut a = Ascii::new(b"\n 1 -2\t3.5 \r\n256\n\nx", 5);
        a.begin().unwrap();
        assert_eq!(a.at(), "line 6");
        assert_eq!(a.value(Scalar::U8), Ok(1.0));
        assert!(a.value(Scalar::U8).is_err(), "-2 is not a uchar");
        assert_eq!(a.value(Scalar::F32), Ok(3.5));
        assert_eq!(a.end(), Ok(()));
        a.begin().unwrap();
        assert!(a.value(Scalar::U8).is_err(), "256 is not a uchar");
        a.begin().unwrap();
        assert_eq!(a.at(), "line 9");
        assert!(a.end().is_err(), "x is left over");
        assert!(a.begin().is_err());
    }
}
