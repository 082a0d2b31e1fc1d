//! Wavefront OBJ importer: a validating scan of the text, then `tobj` for the parse.
//!
//! `tobj` 4 trusts its input in ways that matter here, and its errors carry no line number,
//! so [`scan`] runs first over the same lines, tokenised the same way, with the grammar of
//! `obj_syntax` (shared with the streaming reader), and:
//! - rejects, with its line number, every line `tobj` would fail on: malformed `v`/`vt`/`vn`
//!   lines, `w = 0`, faces without vertices, bad face vertices, `usemtl` without a name;
//! - checks every face index (0, or past the end, or a relative index reaching before the
//!   first element, or a positive one past what `tobj` has read where it resolves it) —
//!   `tobj` does `index * 2 + 1` on texture/normal indices without overflow checks, which
//!   panics in debug builds;
//! - reports NaN/infinite positions (after dividing by `w`) with their line number;
//! - counts triangles against [`ImportLimits::max_triangles`] before `tobj` allocates;
//! - collects `usemtl` names in order of first use, which become the material indices;
//! - blanks (turns into ignored lines) `l` polylines, which `tobj` would otherwise turn into
//!   triangles, and `mtllib` lines, so that `tobj` never parses a `.mtl` file (its MTL parser
//!   unwraps on malformed colour lines, and we only need material names);
//! - blanks vertex colours (`v x y z r g b`), which we do not use and which make `tobj` fail
//!   when only some vertices have them.
//!
//! So `tobj` should never fail; if it does, the error says that its line is unknown.
//!
//! `tobj` then parses with `single_index` (positions, normals and UVs share one index, so a
//! vertex is split wherever its UV or normal differs: seams stay correct) and `triangulate`
//! (polygons become fans around their first vertex; points and lines are ignored). A face of
//! one or two vertices has no triangle: the scan counts it with the degenerate triangles
//! dropped ([`SourceMesh::degenerate_dropped`]), so that the bake reports it.

use std::io::{BufRead, Cursor, Read};
use std::path::{Path, PathBuf};

use super::obj_syntax::{face, numbers, parse_error, position, record_material, usemtl_name, ForwardRefs};
use super::{
    asset_dir, check_triangle_count, check_vertex_count, resolve_inside, ImportErrorKind, ImportLimits, KindResult,
    MeshBuilder,
};
use crate::SourceMesh;

/// What the scan learned about an OBJ file.
#[derive(Debug, Default)]
struct Scan {
    /// `usemtl` names in order of first use; a name's position is its material index.
    material_names: Vec<String>,
    /// Triangles after fan triangulation of every face with three or more vertices.
    triangles: u64,
    /// Faces of one or two vertices (no triangle).
    short_faces: u64,
    /// Byte offsets of keywords to overwrite with `#` (`l`, `mtllib`): tobj ignores them then.
    blank: Vec<usize>,
    /// Byte ranges to overwrite with spaces (vertex colours).
    erase: Vec<std::ops::Range<usize>>,
}

/// The UTF-8 byte order mark some editors put at the start of a text file.
const BOM: &str = "\u{feff}";

/// Imports OBJ text; `bytes` is the whole file (not empty, already size-checked).
pub(super) fn import(mut bytes: Vec<u8>, limits: &ImportLimits) -> KindResult<SourceMesh> {
    // A UTF-8 byte order mark would make tobj ignore the first line; blank it.
    if bytes.starts_with(BOM.as_bytes()) {
        bytes[..BOM.len()].fill(b' ');
    }
    let scan = scan(text(&bytes)?)?;
    check_triangle_count(scan.triangles, limits)?;
    for &offset in &scan.blank {
        bytes[offset] = b'#';
    }
    for range in &scan.erase {
        bytes[range.clone()].fill(b' ');
    }

    // Every usemtl name resolves to its first-use index through one synthetic material
    // library, announced by a synthetic first line (the real `mtllib` lines are blanked).
    let materials: Vec<tobj::Material> =
        scan.material_names.iter().map(|name| tobj::Material { name: name.clone(), ..Default::default() }).collect();
    let load_materials = |_: &Path| -> tobj::MTLLoadResult {
        let by_name = materials.iter().enumerate();
        Ok((materials.clone(), by_name.map(|(i, m)| (m.name.clone(), i)).collect()))
    };
    let options = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
    let mut reader = Cursor::new(&b"mtllib mres-usemtl-names\n"[..]).chain(Cursor::new(&bytes));
    let (models, _) = tobj::load_obj_buf(&mut reader, &options, load_materials).map_err(|e| {
        ImportErrorKind::Parse(format!("{e} (reported by tobj; line unknown: the validating scan missed it)"))
    })?;

    match convert(&models, scan.material_names.len(), scan.triangles, limits) {
        Ok(mut mesh) => {
            mesh.degenerate_dropped += scan.short_faces;
            Ok(mesh)
        }
        Err(ImportErrorKind::NoTriangles { degenerate_dropped }) => {
            Err(ImportErrorKind::NoTriangles { degenerate_dropped: degenerate_dropped + scan.short_faces })
        }
        Err(e) => Err(e),
    }
}

/// Merges the `tobj` models (one per object/group and material) into one mesh.
fn convert(
    models: &[tobj::Model],
    unnamed_material: usize,
    triangles: u64,
    limits: &ImportLimits,
) -> KindResult<SourceMesh> {
    let vertices: usize = models.iter().map(|m| m.mesh.positions.len() / 3).sum();
    check_vertex_count(vertices as u64, limits)?;
    // A model with vertices but without one normal (UV) per vertex means some face vertex
    // had no `vn` (`vt`): drop that attribute for the whole mesh.
    let with_vertices = || models.iter().map(|m| &m.mesh).filter(|m| !m.positions.is_empty());
    let has_normals = with_vertices().all(|m| m.normals.len() == m.positions.len());
    let has_uvs = with_vertices().all(|m| m.texcoords.len() / 2 == m.positions.len() / 3);

    let mut builder = MeshBuilder::new(has_normals, has_uvs, vertices, triangles as usize);
    for model in models {
        let mesh = &model.mesh;
        let count = mesh.positions.len() / 3;
        let base = builder.vertex_count();
        for v in 0..count {
            let at = |data: &[f32], n: usize, k: usize| data.get(n * v + k).copied();
            let position = [0, 1, 2].map(|k| at(&mesh.positions, 3, k).unwrap_or(f32::NAN));
            if !position.iter().all(|c| c.is_finite()) {
                return Err(ImportErrorKind::NonFinitePosition(format!(
                    "{position:?} in object {:?} (after dividing by w)",
                    model.name
                )));
            }
            let normal = [0, 1, 2].map(|k| at(&mesh.normals, 3, k).unwrap_or(0.0));
            let uv = [0, 1].map(|k| at(&mesh.texcoords, 2, k).unwrap_or(0.0));
            builder.push_vertex(position, normal, uv);
        }
        let material = model.mesh.material_id.unwrap_or(unnamed_material) as u32;
        for triangle in mesh.indices.chunks_exact(3) {
            let mut corners = [0u32; 3];
            for (corner, &index) in corners.iter_mut().zip(triangle) {
                // tobj only emits indices of vertices it emitted; checked anyway.
                if index as usize >= count {
                    return Err(ImportErrorKind::IndexOutOfRange {
                        what: format!("object {:?}: parsed vertex", model.name),
                        index: i64::from(index),
                        count: count as u64,
                    });
                }
                *corner = (base + index as usize) as u32;
            }
            builder.push_triangle(corners, material);
        }
    }
    builder.finish()
}

/// The file as text; OBJ files are ASCII in practice, and `tobj` needs UTF-8.
fn text(bytes: &[u8]) -> KindResult<&str> {
    std::str::from_utf8(bytes).map_err(|e| {
        // The same message as the streaming reader's.
        let before = &bytes[..e.valid_up_to()];
        let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
        let column = before.len() - before.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        parse_error(line, &format!("not UTF-8 text (at byte {column} of the line)"))
    })
}

/// Lines of `text` as `tobj` sees them (split at `\n`), with their 1-based numbers and byte
/// offsets.
fn lines(text: &str) -> impl Iterator<Item = (usize, usize, &str)> {
    text.split('\n')
        .scan(0usize, |offset, line| {
            let start = *offset;
            *offset += line.len() + 1;
            Some((start, line))
        })
        .enumerate()
        .map(|(n, (start, line))| (n + 1, start, line))
}

/// Validates faces and vertices and collects what [`import`] needs; see the module docs.
fn scan(text: &str) -> KindResult<Scan> {
    let mut scan = Scan::default();
    let mut counts = [0u64; 3];
    let mut refs = ForwardRefs::default();
    for (line_no, start, line) in lines(text) {
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        let keyword_offset = start + (line.len() - line.trim_start().len());
        match keyword {
            "v" => {
                counts[0] += 1;
                position(words.clone(), line_no)?;
                // `position` allows 0, 1 (w) or 3 (a colour) values after x y z.
                let mut extra = words.skip(3);
                if let (Some(red), Some(_), Some(_)) = (extra.next(), extra.next(), extra.next()) {
                    // Offset of the first colour value: the words are slices of `line`.
                    let from = start + (red.as_ptr() as usize - line.as_ptr() as usize);
                    scan.erase.push(from..start + line.trim_end().len());
                }
            }
            "vt" => {
                counts[1] += 1;
                numbers::<2>(&mut words, line_no, "vt")?;
            }
            "vn" => {
                counts[2] += 1;
                numbers::<3>(&mut words, line_no, "vn")?;
            }
            "l" | "mtllib" => scan.blank.push(keyword_offset),
            "o" | "g" => refs.object(&counts)?,
            "usemtl" => {
                record_material(&mut scan.material_names, line, line_no)?;
                refs.material(usemtl_name(line), &counts)?;
            }
            "f" => {
                // Resolved as tobj will: relative indices against the counts so far.
                let mut corners = 0u64;
                face(words, line_no, &counts, Some(&mut refs), |_| corners += 1)?;
                scan.triangles += corners.saturating_sub(2);
                scan.short_faces += u64::from(corners < 3);
            }
            _ => {}
        }
    }
    refs.end(&counts)?;
    Ok(scan)
}

/// The `mtllib` files of an OBJ that exist inside its directory, in order of first mention.
///
/// `tobj` reads the rest of an `mtllib` line as one file name; the OBJ spec allows several
/// names separated by spaces. Both readings are tried: the whole rest if it names a file,
/// else each word.
pub(super) fn referenced_files(path: &Path, bytes: &[u8]) -> KindResult<Vec<PathBuf>> {
    let dir = asset_dir(path);
    let mut files: Vec<PathBuf> = Vec::new();
    let mut add = |file: PathBuf| {
        if !files.contains(&file) {
            files.push(file);
        }
    };
    let text = text(bytes)?;
    for line in Cursor::new(text.strip_prefix(BOM).unwrap_or(text)).lines() {
        let line = line.map_err(ImportErrorKind::Io)?;
        if line.split_whitespace().next() != Some("mtllib") {
            continue;
        }
        let rest = line.trim_start()["mtllib".len()..].trim();
        let existing = |name: &str| resolve_inside(&dir, name).filter(|p| p.is_file());
        if let Some(file) = existing(rest) {
            add(file);
        } else {
            rest.split_whitespace().filter_map(existing).for_each(&mut add);
        }
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn import_str(text: &str) -> KindResult<SourceMesh> {
        import(text.as_bytes().to_vec(), &ImportLimits::default())
    }

    #[test]
    fn usemtl_without_library_numbers_by_first_use() {
        let mesh = import_str(
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n\
             f 1 2 3\nusemtl b\nf 2 4 3\nusemtl a\nf 1 2 4\nusemtl b\nf 1 4 3\n",
        )
        .unwrap();
        // Faces before any usemtl get one past the named materials (2).
        assert_eq!(mesh.materials, vec![2, 0, 1, 0]);
    }

    #[test]
    fn polylines_and_points_are_not_triangles() {
        let err = import_str("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\nf 1\nf 1 2\n").unwrap_err();
        assert!(matches!(err, ImportErrorKind::NoTriangles { .. }), "{err}");
    }

    #[test]
    fn zero_and_overflowing_indices_are_errors_not_panics() {
        for face in [
            "f 1/0 2/1 3/1",
            "f 1//0 2//1 3//1",
            "f 1/-9223372036854775808 2/1 3/1",
            "f 1/9223372036854775807 2/1 3/1",
            "f -4 1 2",
            "f 0 1 2",
            "f 1 2 4",
        ] {
            let text = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n{face}\n");
            let err = import_str(&text).unwrap_err();
            assert!(matches!(err, ImportErrorKind::IndexOutOfRange { .. }), "{face}: {err}");
        }
    }

    #[test]
    fn bom_is_ignored() {
        let mesh = import_str("\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(mesh.triangle_count(), 1);
    }
}
