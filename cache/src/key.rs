//! The cache key: built in one place ([`CacheKey::new`]) from an explicit list of inputs
//! ([`KeyInputs`]), and mapped to a path in one place ([`entry_path`]).

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// Version of the key encoding itself (the tags, order and length prefixes below). Bump it
/// whenever [`CacheKey::new`] changes what it hashes or how, so old entries stop matching.
pub const KEY_SCHEMA_VERSION: u32 = 1;

/// blake3 `derive_key` context: separates cache keys from every other blake3 use.
const KEY_CONTEXT: &str = "mres-cache 2025 cache key";

/// Everything a cache key is built from, in one place. Each field is hashed with a
/// domain-separation tag and its length (exact encoding in `cache/README.md`), so no two
/// different inputs can produce the same byte stream.
#[derive(Clone, Debug)]
pub struct KeyInputs<'a> {
    /// The asset file's bytes, exactly as read from disk.
    pub input_bytes: &'a [u8],
    /// Every file the asset references (`.mtl`, `.bin`, textures the bake reads …), as
    /// (path relative to the asset, bytes). The caller should sort by name; [`CacheKey::new`]
    /// sorts again (by name bytes, then content) so the order never matters. Use `/` as the
    /// separator so keys agree across platforms.
    pub referenced: Vec<(String, Vec<u8>)>,
    /// The effective settings for this asset as canonical text (the caller serializes the
    /// settings struct deterministically, e.g. TOML or JSON with fixed field order).
    pub settings: &'a str,
    /// The `.mres` format version the baker writes.
    pub format_version: u32,
    /// The baker's algorithm version constant, bumped whenever its output would change.
    pub baker_version: u32,
}

/// A 32-byte blake3 cache key. `Display` and [`FromStr`] use 64 lowercase hex characters
/// (parsing also accepts uppercase).
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CacheKey([u8; 32]);

impl CacheKey {
    /// Builds the key from `inputs`. Fields are hashed in this order, each as
    /// `tag (4 ASCII bytes) ‖ length (u64 LE) ‖ bytes`: `KSCH` (the key schema version),
    /// `FMTV` (format version, u32 LE), `BAKV` (baker version, u32 LE), `SETT` (settings,
    /// UTF-8), `INPT` (input bytes), `NREF` (number of referenced files, u64 LE), then for each
    /// referenced file sorted by name: `RNAM` (name, UTF-8) and `RDAT` (bytes).
    pub fn new(inputs: &KeyInputs) -> CacheKey {
        let mut h = blake3::Hasher::new_derive_key(KEY_CONTEXT);
        field(&mut h, b"KSCH", &KEY_SCHEMA_VERSION.to_le_bytes());
        field(&mut h, b"FMTV", &inputs.format_version.to_le_bytes());
        field(&mut h, b"BAKV", &inputs.baker_version.to_le_bytes());
        field(&mut h, b"SETT", inputs.settings.as_bytes());
        field(&mut h, b"INPT", inputs.input_bytes);
        let mut refs: Vec<&(String, Vec<u8>)> = inputs.referenced.iter().collect();
        // Content as a tie-break keeps the key independent of order even if a caller passes
        // the same name twice.
        refs.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()).then_with(|| a.1.cmp(&b.1)));
        field(&mut h, b"NREF", &(refs.len() as u64).to_le_bytes());
        for (name, bytes) in refs {
            field(&mut h, b"RNAM", name.as_bytes());
            field(&mut h, b"RDAT", bytes);
        }
        CacheKey(*h.finalize().as_bytes())
    }

    /// The key of a mesh by its content rather than by the file it came from, so that the
    /// same mesh in different assets (or placed by several nodes) shares one entry. Hashes
    /// `KSCH`, `FMTV`, `BAKV`, `SETT` as [`CacheKey::new`] does, then `MESH` (the caller's
    /// 32-byte hash of the mesh's triangles and attributes) instead of `INPT`; no
    /// referenced files. A distinct tag, so no file key equals a mesh key.
    pub fn for_mesh(content_hash: &[u8; 32], settings: &str, format_version: u32, baker_version: u32) -> CacheKey {
        let mut h = blake3::Hasher::new_derive_key(KEY_CONTEXT);
        field(&mut h, b"KSCH", &KEY_SCHEMA_VERSION.to_le_bytes());
        field(&mut h, b"FMTV", &format_version.to_le_bytes());
        field(&mut h, b"BAKV", &baker_version.to_le_bytes());
        field(&mut h, b"SETT", settings.as_bytes());
        field(&mut h, b"MESH", content_hash);
        CacheKey(*h.finalize().as_bytes())
    }

    /// Wraps raw key bytes (e.g. read back from a report).
    pub fn from_bytes(bytes: [u8; 32]) -> CacheKey {
        CacheKey(bytes)
    }

    /// The raw 32 key bytes.
    pub fn as_bytes(&self) -> &[u8; 32] {
        &self.0
    }

    /// The key as 64 lowercase hex characters (same as `Display`).
    pub fn hex(&self) -> String {
        self.to_string()
    }
}

fn field(h: &mut blake3::Hasher, tag: &[u8; 4], bytes: &[u8]) {
    h.update(tag);
    h.update(&(bytes.len() as u64).to_le_bytes());
    h.update(bytes);
}

impl fmt::Display for CacheKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for b in self.0 {
            write!(f, "{b:02x}")?;
        }
        Ok(())
    }
}

impl fmt::Debug for CacheKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "CacheKey({self})")
    }
}

/// A string that is not 64 hex characters, given to `CacheKey::from_str`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseKeyError {
    /// The string is not 64 characters long.
    #[error("a cache key is 64 hex characters, got {len}")]
    WrongLength {
        /// Length of the string given, in bytes.
        len: usize,
    },
    /// A character is not a hex digit.
    #[error("a cache key is hex, found {found:?} at byte {at}")]
    NotHex {
        /// Byte offset of the bad character.
        at: usize,
        /// The bad character.
        found: char,
    },
}

impl FromStr for CacheKey {
    type Err = ParseKeyError;

    fn from_str(s: &str) -> Result<CacheKey, ParseKeyError> {
        if s.len() != 64 {
            return Err(ParseKeyError::WrongLength { len: s.len() });
        }
        let mut out = [0u8; 32];
        for (at, c) in s.char_indices() {
            let v = c.to_digit(16).ok_or(ParseKeyError::NotHex { at, found: c })? as u8;
            out[at / 2] |= if at % 2 == 0 { v << 4 } else { v };
        }
        Ok(CacheKey(out))
    }
}

/// The one mapping from key to entry: `"ab/cdef….mres"` relative to the cache root, a
/// 2-hex-character fan-out directory (256 of them) holding files named by the remaining 62 hex
/// characters plus `.mres`.
pub fn entry_path(key: &CacheKey) -> PathBuf {
    let hex = key.hex();
    let mut p = PathBuf::from(&hex[..2]);
    p.push(format!("{}.mres", &hex[2..]));
    p
}

/// The inverse of [`entry_path`] for one file: the key a fan-out directory name and file name
/// stand for, or `None` if they are not exactly what [`entry_path`] would produce.
pub(crate) fn key_from_entry_name(dir: &str, file: &str) -> Option<CacheKey> {
    let stem = file.strip_suffix(".mres")?;
    let is_lower_hex = |s: &str| s.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b));
    if dir.len() != 2 || stem.len() != 62 || !is_lower_hex(dir) || !is_lower_hex(stem) {
        return None;
    }
    format!("{dir}{stem}").parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    type Refs = Vec<(String, Vec<u8>)>;

    fn base() -> (Vec<u8>, Refs, String) {
        (
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nmtllib a.mtl\n".to_vec(),
            vec![("a.mtl".to_string(), b"newmtl red\n".to_vec()), ("tex/b.bin".to_string(), vec![1, 2, 3])],
            "max_triangles = 128\n".to_string(),
        )
    }

    fn key_of(input: &[u8], refs: Refs, settings: &str, fmt: u32, baker: u32) -> CacheKey {
        CacheKey::new(&KeyInputs {
            input_bytes: input,
            referenced: refs,
            settings,
            format_version: fmt,
            baker_version: baker,
        })
    }

    #[test]
    fn equal_inputs_equal_keys() {
        let (input, refs, settings) = base();
        let a = key_of(&input, refs.clone(), &settings, 3, 7);
        let b = key_of(&input.clone(), refs, &settings.clone(), 3, 7);
        assert_eq!(a, b);
    }

    #[test]
    fn each_input_changes_the_key() {
        let (input, refs, settings) = base();
        let k0 = key_of(&input, refs.clone(), &settings, 3, 7);
        let mut keys = vec![k0];

        let mut other_input = input.clone();
        other_input[0] ^= 1;
        keys.push(key_of(&other_input, refs.clone(), &settings, 3, 7));
        for i in 0..refs.len() {
            let mut r = refs.clone();
            r[i].1.push(0);
            keys.push(key_of(&input, r, &settings, 3, 7));
            let mut r = refs.clone();
            r[i].0.push('x');
            keys.push(key_of(&input, r, &settings, 3, 7));
        }
        let mut fewer = refs.clone();
        fewer.pop();
        keys.push(key_of(&input, fewer, &settings, 3, 7));
        keys.push(key_of(&input, refs.clone(), "max_triangles = 126\n", 3, 7));
        keys.push(key_of(&input, refs.clone(), &settings, 4, 7));
        keys.push(key_of(&input, refs.clone(), &settings, 3, 8));
        // Swapping the two versions must not collide either (each has its own tag).
        keys.push(key_of(&input, refs.clone(), &settings, 7, 3));

        for i in 0..keys.len() {
            for j in i + 1..keys.len() {
                assert_ne!(keys[i], keys[j], "variants {i} and {j} collide");
            }
        }
    }

    #[test]
    fn moving_bytes_between_fields_changes_the_key() {
        // Length prefixes: "ab" + "c" must differ from "a" + "bc".
        let a = key_of(b"ab", vec![], "c", 1, 1);
        let b = key_of(b"a", vec![], "bc", 1, 1);
        assert_ne!(a, b);
        let a = key_of(b"", vec![("ab".into(), b"c".to_vec())], "", 1, 1);
        let b = key_of(b"", vec![("a".into(), b"bc".to_vec())], "", 1, 1);
        assert_ne!(a, b);
    }

    #[test]
    fn referenced_order_does_not_matter() {
        let (input, refs, settings) = base();
        let mut rev = refs.clone();
        rev.reverse();
        assert_eq!(key_of(&input, refs, &settings, 3, 7), key_of(&input, rev, &settings, 3, 7));
    }

    #[test]
    fn mesh_keys_depend_on_each_input_and_differ_from_file_keys() {
        let (_, _, settings) = base();
        let hash = [7u8; 32];
        let mesh = CacheKey::for_mesh(&hash, &settings, 2, 4);
        assert_eq!(mesh, CacheKey::for_mesh(&hash, &settings, 2, 4));
        assert_ne!(mesh, CacheKey::for_mesh(&[8u8; 32], &settings, 2, 4));
        assert_ne!(mesh, CacheKey::for_mesh(&hash, "other", 2, 4));
        assert_ne!(mesh, CacheKey::for_mesh(&hash, &settings, 3, 4));
        assert_ne!(mesh, CacheKey::for_mesh(&hash, &settings, 2, 5));
        assert_ne!(mesh, key_of(&hash, Vec::new(), &settings, 2, 4));
    }

    #[test]
    fn hex_display_and_parse_round_trip() {
        let (input, refs, settings) = base();
        let k = key_of(&input, refs, &settings, 3, 7);
        let hex = k.hex();
        assert_eq!(hex.len(), 64);
        assert!(hex.bytes().all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase()));
        assert_eq!(format!("{k}"), hex);
        assert_eq!(hex.parse::<CacheKey>(), Ok(k));
        assert_eq!(hex.to_uppercase().parse::<CacheKey>(), Ok(k));
        assert_eq!("abc".parse::<CacheKey>(), Err(ParseKeyError::WrongLength { len: 3 }));
        let bad = format!("{}g", &hex[..63]);
        assert_eq!(bad.parse::<CacheKey>(), Err(ParseKeyError::NotHex { at: 63, found: 'g' }));
        // Multi-byte characters must not panic.
        let bad = format!("{}é", &hex[..62]);
        assert!(bad.parse::<CacheKey>().is_err());
    }

    #[test]
    fn entry_path_layout_and_inverse() {
        let k: CacheKey = "00ff".repeat(16).parse().unwrap();
        let p = entry_path(&k);
        assert_eq!(p, PathBuf::from("00").join(format!("ff{}.mres", "00ff".repeat(15))));
        let dir = p.parent().unwrap().to_str().unwrap();
        let file = p.file_name().unwrap().to_str().unwrap();
        assert_eq!(key_from_entry_name(dir, file), Some(k));
        // Another fan-out directory names another key: the path is the key.
        assert_ne!(key_from_entry_name("01", file), Some(k));
        assert_eq!(key_from_entry_name(dir, &file.to_uppercase().replace(".MRES", ".mres")), None);
        assert_eq!(key_from_entry_name(dir, "x.mres"), None);
        assert_eq!(key_from_entry_name(dir, &file.replace(".mres", ".tmp")), None);
    }
}
