//! Bit packing and octahedral normals: the two encodings of the page layout (FORMAT.md §5).

/// Appends values of a fixed bit width to a stream of little-endian u32 words, LSB first.
#[derive(Default)]
pub struct BitWriter {
    words: Vec<u32>,
    bit: u64,
}

impl BitWriter {
    /// A writer with room for `bits` bits, so that pushing them never reallocates.
    pub fn with_capacity(bits: u64) -> BitWriter {
        BitWriter { words: Vec::with_capacity(bits.div_ceil(32) as usize), bit: 0 }
    }

    /// Appends the low `bits` bits of `value` (`bits` ≤ 32).
    pub fn push(&mut self, value: u32, bits: u32) {
        if bits == 0 {
            return;
        }
        let value = if bits == 32 { value } else { value & ((1u32 << bits) - 1) } as u64;
        let word = (self.bit / 32) as usize;
        let shift = self.bit % 32;
        let needed = ((self.bit + bits as u64).div_ceil(32)) as usize;
        self.words.resize(needed.max(self.words.len()), 0);
        let wide = value << shift;
        self.words[word] |= wide as u32;
        if shift + bits as u64 > 32 {
            self.words[word + 1] |= (wide >> 32) as u32;
        }
        self.bit += bits as u64;
    }

    /// The packed words.
    pub fn finish(self) -> Vec<u32> {
        self.words
    }
}

/// Reads value `index` of width `bits` from a packed stream; `None` when out of range.
pub fn read_bits(words: &[u8], bit_offset: u64, bits: u32) -> Option<u32> {
    if bits == 0 {
        return Some(0);
    }
    let word = usize::try_from(bit_offset / 32).ok()?;
    let shift = bit_offset % 32;
    let load = |i: usize| -> Option<u64> {
        let b = words.get(i * 4..i * 4 + 4)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64)
    };
    let mut wide = load(word)?;
    if shift + bits as u64 > 32 {
        wide |= load(word + 1)? << 32;
    }
    let mask = if bits == 32 { u32::MAX as u64 } else { (1u64 << bits) - 1 };
    Some(((wide >> shift) & mask) as u32)
}

/// Number of bits needed to store values `0..=max`.
pub fn bits_for(max: u32) -> u32 {
    32 - max.leading_zeros()
}

fn sign(v: f32) -> f32 {
    if v < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// Encodes a unit normal as two unsigned `bits`-bit octahedral coordinates.
/// A zero or non-finite normal encodes as +Z.
pub fn oct_encode(n: [f32; 3], bits: u32) -> [u32; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (mut x, mut y) = if l1 > 0.0 && l1.is_finite() { (n[0] / l1, n[1] / l1) } else { (0.0, 0.0) };
    if l1 > 0.0 && n[2] < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * sign(ox);
        y = (1.0 - ox.abs()) * sign(oy);
    }
    let max = ((1u32 << bits) - 1) as f32;
    let q = |v: f32| ((v * 0.5 + 0.5) * max).round().clamp(0.0, max) as u32;
    [q(x), q(y)]
}

/// Decodes two `bits`-bit octahedral coordinates to a unit normal (FORMAT.md §5.4).
pub fn oct_decode(q: [u32; 2], bits: u32) -> [f32; 3] {
    let max = ((1u32 << bits) - 1) as f32;
    let mut x = q[0] as f32 / max * 2.0 - 1.0;
    let mut y = q[1] as f32 / max * 2.0 - 1.0;
    let z = 1.0 - x.abs() - y.abs();
    if z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * sign(ox);
        y = (1.0 - ox.abs()) * sign(oy);
    }
    let len = (x * x + y * y + z * z).sqrt();
    [x / len, y / len, z / len]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_stream_round_trips_every_width() {
        let mut w = BitWriter::default();
        let mut expected = Vec::new();
        for bits in 0..=32u32 {
            for i in 0..5u32 {
                let v =
                    if bits == 32 { u32::MAX - i } else { i.wrapping_mul(2654435761) & ((1u64 << bits) - 1) as u32 };
                w.push(v, bits);
                expected.push((v, bits));
            }
        }
        let bytes: Vec<u8> = w.finish().iter().flat_map(|x| x.to_le_bytes()).collect();
        let mut at = 0u64;
        for (v, bits) in expected {
            assert_eq!(read_bits(&bytes, at, bits), Some(v), "width {bits}");
            at += bits as u64;
        }
        assert_eq!(read_bits(&bytes, bytes.len() as u64 * 8, 1), None);
    }

    #[test]
    fn octahedral_error_is_small() {
        for i in 0..2000 {
            let t = i as f32 * 0.37;
            let n = [t.sin() * (t * 0.7).cos(), (t * 1.3).cos(), (t * 0.3).sin() - 0.2];
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let n = [n[0] / len, n[1] / len, n[2] / len];
            let d = oct_decode(oct_encode(n, 12), 12);
            let dot = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
            assert!(dot > 0.99995, "{n:?} -> {d:?}");
        }
        assert_eq!(bits_for(0), 0);
        assert_eq!(bits_for(1), 1);
        assert_eq!(bits_for(255), 8);
        assert_eq!(bits_for(256), 9);
    }
}
