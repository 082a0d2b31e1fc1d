//! The OBJ grammar both OBJ readers share (the whole-file `obj` importer and the streaming
//! `obj_stream` reader): `v`/`vt`/`vn` values, face-vertex resolution, when positive indices
//! are checked, `usemtl` names and the error messages, so that both accept and reject exactly
//! the same lines, and every error names its line.
//!
//! The rules are `tobj`'s (which the whole-file importer parses with after its scan), made
//! into errors with line numbers where `tobj` would fail without one.

use super::{ImportErrorKind, KindResult};
use crate::mesh::{Corner, NONE};

/// Element kinds a face index can refer to, in the order of the `v/vt/vn` slots.
pub(crate) const SLOTS: [&str; 3] = ["vertex position", "texture coordinate", "normal"];

/// Adds a `usemtl` line's name to `names` (in order of first use), extracting it as tobj
/// does so that the names match its lookups.
pub(crate) fn record_material(names: &mut Vec<String>, line: &str, line_no: usize) -> KindResult<()> {
    let name = usemtl_name(line);
    if name.is_empty() {
        return Err(parse_error(line_no, "usemtl without a material name"));
    }
    if !names.iter().any(|n| n == name) {
        names.push(name.to_owned());
    }
    Ok(())
}

/// The material name of a `usemtl` line, as tobj reads it.
pub(crate) fn usemtl_name(line: &str) -> &str {
    line.split_once(' ').unwrap_or_default().1.trim()
}

pub(crate) fn parse_error(line_no: usize, message: &str) -> ImportErrorKind {
    ImportErrorKind::Parse(format!("line {line_no}: {message}"))
}

pub(crate) fn out_of_range(line_no: usize, slot: usize, index: i64, count: u64) -> ImportErrorKind {
    ImportErrorKind::IndexOutOfRange { what: format!("line {line_no}: {}", SLOTS[slot]), index, count }
}

/// Resolves one `v/vt/vn` face vertex against the element counts so far. With
/// `max_positive`, records the largest positive index per slot (checked at the end of pass 1,
/// as positive indices refer to the whole file).
pub(crate) fn corner(
    vertex: &str,
    line_no: usize,
    counts: &[u64; 3],
    mut max_positive: Option<&mut [(u64, usize); 3]>,
) -> KindResult<Corner> {
    let mut out = [NONE; 3];
    for (slot, part) in vertex.split('/').enumerate() {
        if part.is_empty() {
            if slot == 0 {
                return Err(parse_error(line_no, "face vertex without a position index"));
            }
            continue;
        }
        let (Some(_), Ok(index)) = (SLOTS.get(slot), part.parse::<i64>()) else {
            return Err(parse_error(line_no, &format!("bad face vertex {vertex:?}")));
        };
        let count = counts[slot];
        let magnitude = index.unsigned_abs();
        if index == 0 || (index < 0 && magnitude > count) || magnitude > u32::MAX as u64 {
            return Err(out_of_range(line_no, slot, index, count));
        }
        if let Some(max) = max_positive.as_deref_mut() {
            if index > 0 && magnitude > max[slot].0 {
                max[slot] = (magnitude, line_no);
            }
        }
        out[slot] = if index > 0 { (index - 1) as u32 } else { (count - magnitude) as u32 };
    }
    Ok(Corner { v: out[0], vt: out[1], vn: out[2] })
}

/// The first `N` numbers after a keyword (more are ignored, as tobj does).
pub(crate) fn numbers<'a, const N: usize>(
    words: &mut impl Iterator<Item = &'a str>,
    line_no: usize,
    keyword: &str,
) -> KindResult<[f32; N]> {
    let mut out = [0.0f32; N];
    for x in out.iter_mut() {
        let w =
            words.next().ok_or_else(|| parse_error(line_no, &format!("{keyword} line with fewer than {N} numbers")))?;
        *x = w.parse().map_err(|_| parse_error(line_no, &format!("bad number {w:?} in a {keyword} line")))?;
    }
    Ok(out)
}

/// A `v` line after its keyword, read as tobj reads it: `x y z`, then nothing, `w` (which
/// divides the coordinates; 0 is an error) or three colour values (ignored). The position
/// must be finite (after the division).
pub(crate) fn position(mut words: std::str::SplitWhitespace<'_>, line_no: usize) -> KindResult<[f32; 3]> {
    let p = numbers::<3>(&mut words, line_no, "v")?;
    let p = match (words.next(), words.next(), words.next(), words.next()) {
        (None, ..) => p,
        (Some(w), None, ..) => {
            let w: f32 = w.parse().map_err(|_| parse_error(line_no, &format!("bad w {w:?} in a v line")))?;
            if w == 0.0 {
                return Err(parse_error(line_no, "v line with w = 0"));
            }
            p.map(|c| c / w)
        }
        (Some(_), Some(_), Some(_), None) => p, // a vertex colour
        _ => return Err(parse_error(line_no, "v line with 2 or more than 3 values after x y z")),
    };
    if !p.iter().all(|c| c.is_finite()) {
        return Err(ImportErrorKind::NonFinitePosition(format!("line {line_no}: v {p:?}")));
    }
    Ok(p)
}

/// The face vertices of an `f` line after its keyword, resolved against the element counts
/// so far; `refs` records the positive indices for [`ForwardRefs`]. A face without vertices
/// is an error (tobj fails on it as an invalid polygon).
pub(crate) fn face<'a>(
    words: impl Iterator<Item = &'a str>,
    line_no: usize,
    counts: &[u64; 3],
    mut refs: Option<&mut ForwardRefs>,
    mut f: impl FnMut(Corner),
) -> KindResult<()> {
    let mut any = false;
    for vertex in words {
        f(corner(vertex, line_no, counts, refs.as_deref_mut().map(|r| &mut r.max))?);
        any = true;
    }
    if !any {
        return Err(parse_error(line_no, "face without vertices"));
    }
    if let Some(refs) = refs {
        refs.faces = true;
    }
    Ok(())
}

/// Positive face indices waiting for their check. tobj resolves them when it closes a model
/// (at an `o`/`g` line or a change of material after faces, and at the end of the file)
/// against the elements read up to there, so a face may refer ahead only that far.
#[derive(Debug, Default)]
pub(crate) struct ForwardRefs {
    /// Largest positive index per slot since the last check, and its line.
    max: [(u64, usize); 3],
    /// A face was read since the last check.
    faces: bool,
    /// The last `usemtl` name.
    material: Option<String>,
}

impl ForwardRefs {
    /// An `o` or `g` line.
    pub(crate) fn object(&mut self, counts: &[u64; 3]) -> KindResult<()> {
        if self.faces {
            self.check(counts)?;
        }
        Ok(())
    }

    /// A `usemtl` line naming `name`.
    pub(crate) fn material(&mut self, name: &str, counts: &[u64; 3]) -> KindResult<()> {
        if self.material.as_deref() != Some(name) {
            if self.faces {
                self.check(counts)?;
            }
            self.material = Some(name.to_owned());
        }
        Ok(())
    }

    /// The end of the file.
    pub(crate) fn end(&mut self, counts: &[u64; 3]) -> KindResult<()> {
        self.check(counts)
    }

    fn check(&mut self, counts: &[u64; 3]) -> KindResult<()> {
        for (slot, &(index, line_no)) in self.max.iter().enumerate() {
            if index > counts[slot] {
                return Err(out_of_range(line_no, slot, index as i64, counts[slot]));
            }
        }
        self.max = [(0, 0); 3];
        self.faces = false;
        Ok(())
    }
}
