//! The PLY header: `ply`, `format`, `element` and `property` lines up to `end_header`.

use crate::{ImportErrorKind, KindResult};

/// How the body after `end_header` is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Encoding {
    /// Whitespace-separated numbers, one element per line.
    Ascii,
    /// Packed values, little endian.
    BinaryLittleEndian,
    /// Packed values, big endian.
    BinaryBigEndian,
}

/// A property's value type (`char`/`int8` … `double`/`float64`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// Bytes per value in a binary body.
    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    pub(super) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
}

impl std::fmt::Display for Scalar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let name = match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        };
        f.write_str(name)
    }
}

/// A property's type: one value, or a list (count, then that many items).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PropertyType {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Property {
    pub name: String,
    pub ty: PropertyType,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Element {
    pub name: String,
    /// Entries as declared; checked against the body's size before anything is allocated.
    pub count: u64,
    pub properties: Vec<Property>,
    /// Header line of the `element` line, for messages.
    pub line: usize,
}

impl Element {
    /// Index of the property `name`, if any.
    pub(super) fn property(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p.name == name)
    }

    /// The fewest bytes one entry can take in `encoding`: binary, the scalars' sizes plus the
    /// lists' count fields (empty lists); ASCII, one digit and one separator per value.
    pub(super) fn min_entry_bytes(&self, encoding: Encoding) -> u64 {
        match encoding {
            Encoding::Ascii => 2 * self.properties.len() as u64,
            _ => self
                .properties
                .iter()
                .map(|p| match p.ty {
                    PropertyType::Scalar(s) => s.size() as u64,
                    PropertyType::List { count, .. } => count.size() as u64,
                })
                .sum(),
        }
    }

    /// Bytes of one binary entry if it has no lists (all entries the same size).
    pub(super) fn fixed_binary_size(&self) -> Option<u64> {
        let scalar = |p: &Property| match p.ty {
            PropertyType::Scalar(s) => Some(s.size() as u64),
            PropertyType::List { .. } => None,
        };
        self.properties.iter().map(scalar).sum()
    }
}

#[derive(Debug)]
pub(super) struct Header {
    pub encoding: Encoding,
    pub elements: Vec<Element>,
    /// Byte offset of the body (just after the `end_header` line).
    pub body_start: usize,
    /// Number of header lines (the body's first line is `lines + 1`).
    pub lines: usize,
}

pub(super) fn header_error(line: usize, message: &str) -> ImportErrorKind {
    ImportErrorKind::Parse(format!("line {line}: {message}"))
}

/// Parses the header at the start of `bytes`.
pub(super) fn parse(bytes: &[u8]) -> KindResult<Header> {
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut offset = 0usize;
    let mut line_no = 0usize;
    while offset < bytes.len() {
        let end = bytes[offset..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |i| offset + i);
        let raw = &bytes[offset..end];
        offset = (end + 1).min(bytes.len());
        line_no += 1;
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        if line_no == 1 {
            if raw.trim_ascii() != b"ply" {
                return Err(header_error(1, "not a PLY file (the first line is not \"ply\")"));
            }
            continue;
        }
        // Comments may be in any encoding; nothing else in a header needs more than ASCII.
        let first = raw.trim_ascii_start().split(|b| b.is_ascii_whitespace()).next().unwrap_or_default();
        if first == b"comment" || first == b"obj_info" {
            continue;
        }
        let text = std::str::from_utf8(raw).map_err(|_| header_error(line_no, "header line is not ASCII text"))?;
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        match words.as_slice() {
            [] => {}
            ["end_header"] => {
                let encoding = encoding.ok_or_else(|| header_error(line_no, "no format line before end_header"))?;
                return Ok(Header { encoding, elements, body_start: offset, lines: line_no });
            }
            ["format", rest @ ..] => {
                if encoding.is_some() {
                    return Err(header_error(line_no, "second format line"));
                }
                encoding = Some(format(rest, line_no)?);
            }
            ["element", name, count] => {
                let count = count.parse::<u64>().map_err(|_| {
                    header_error(line_no, &format!("element count {count:?} is not a non-negative integer"))
                })?;
                if elements.iter().any(|e| e.name == *name) {
                    return Err(header_error(line_no, &format!("second element named {name:?}")));
                }
                elements.push(Element { name: name.to_string(), count, properties: Vec::new(), line: line_no });
            }
            ["element", ..] => return Err(header_error(line_no, "expected \"element NAME COUNT\"")),
            ["property", rest @ ..] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| header_error(line_no, "property line before any element line"))?;
                let property = property(rest, line_no)?;
                if element.property(&property.name).is_some() {
                    let message = format!("element {:?} has a second property {:?}", element.name, property.name);
                    return Err(header_error(line_no, &message));
                }
                element.properties.push(property);
            }
            [keyword, ..] => return Err(header_error(line_no, &format!("unknown header keyword {keyword:?}"))),
        }
    }
    Err(header_error(line_no.max(1), "the file ends before end_header (truncated, or not a PLY file)"))
}

fn format(words: &[&str], line_no: usize) -> KindResult<Encoding> {
    let encoding = match words {
        [encoding, "1.0" | "1"] => *encoding,
        [_, version] => return Err(header_error(line_no, &format!("unsupported PLY version {version:?}"))),
        _ => return Err(header_error(line_no, "expected \"format ENCODING 1.0\"")),
    };
    match encoding {
        "ascii" => Ok(Encoding::Ascii),
        "binary_little_endian" => Ok(Encoding::BinaryLittleEndian),
        "binary_big_endian" => Ok(Encoding::BinaryBigEndian),
        _ => Err(header_error(line_no, &format!("unknown encoding {encoding:?}"))),
    }
}

fn property(words: &[&str], line_no: usize) -> KindResult<Property> {
    let scalar = |name: &str| {
        Scalar::from_name(name).ok_or_else(|| header_error(line_no, &format!("unknown property type {name:?}")))
    };
    match words {
        ["list", count, item, name] => {
            let count = scalar(count)?;
            if !count.is_integer() {
                return Err(header_error(line_no, &format!("list {name:?} has a floating-point count type")));
            }
            Ok(Property { name: name.to_string(), ty: PropertyType::List { count, item: scalar(item)? } })
        }
        [ty, name] if *ty != "list" => Ok(Property { name: name.to_string(), ty: PropertyType::Scalar(scalar(ty)?) }),
        _ => Err(header_error(line_no, "expected \"property TYPE NAME\" or \"property list COUNT_TYPE TYPE NAME\"")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_types_lists_and_body_offset() {
        let text = "ply\r\nformat binary_big_endian 1.0\r\ncomment caf\u{e9}\r\nelement vertex 2\r\n\
                    property float64 x\r\nproperty list uint8 int vertex_indices\r\nend_header\r\nBODY";
        let header = parse(text.as_bytes()).unwrap();
        assert_eq!(header.encoding, Encoding::BinaryBigEndian);
        assert_eq!(header.lines, 7);
        assert_eq!(&text.as_bytes()[header.body_start..], b"BODY");
        let e = &header.elements[0];
        assert_eq!((e.name.as_str(), e.count, e.line), ("vertex", 2, 4));
        assert_eq!(e.properties[0].ty, PropertyType::Scalar(Scalar::F64));
        assert_eq!(e.properties[1].ty, PropertyType::List { count: Scalar::U8, item: Scalar::I32 });
        assert_eq!(e.min_entry_bytes(Encoding::BinaryBigEndian), 9);
        assert_eq!(e.fixed_binary_size(), None);
    }

    #[test]
    fn bad_headers_name_their_line() {
        for (text, expect) in [
            ("plx\n", "line 1: not a PLY file"),
            ("ply\nformat ascii 1.0\nelement vertex\n", "line 3: expected \"element"),
            ("ply\nformat ascii 1.0\nelement vertex -1\n", "line 3: element count"),
            ("ply\nformat ascii 2.0\n", "line 2: unsupported PLY version"),
            ("ply\nformat ascii 1.0\nproperty float x\n", "line 3: property line before"),
            ("ply\nformat ascii 1.0\nelement v 1\nproperty flaot x\n", "line 4: unknown property type"),
            ("ply\nformat ascii 1.0\nelement v 1\nproperty list float int x\n", "line 4: list \"x\" has a float"),
            ("ply\nformat ascii 1.0\nelement v 1\nelement v 2\n", "line 4: second element"),
            ("ply\nformat ascii 1.0\nelement v 1\nproperty int x\nproperty int x\n", "line 5: element \"v\" has a"),
            ("ply\nelement v 1\nend_header\n", "line 3: no format line"),
            ("ply\nformat ascii 1.0\nelement v 1\n", "line 3: the file ends before end_header"),
            ("ply\nformat ascii 1.0\nvertex 3\n", "line 3: unknown header keyword"),
        ] {
            let err = parse(text.as_bytes()).unwrap_err().to_string();
            assert!(err.contains(expect), "{text:?}: {err}");
        }
    }
}
