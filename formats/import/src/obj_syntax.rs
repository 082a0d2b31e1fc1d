//! The OBJ grammar both OBJ readers share (the whole-file `obj` importer and the streaming
//! `obj_stream` reader): face-vertex resolution, `usemtl` names and the error messages, so
//! that both accept and reject exactly the same lines.

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
