//! Streaming OBJ reading, for meshes too large to hold as text plus a [`crate::SourceMesh`]
//! (the `tobj` path needs the whole file and its own arrays: about 290 bytes per triangle).
//!
//! Two passes over the file, each holding one line at a time:
//! 1. [`ObjVertices::read`] keeps the vertex attributes (`v`, `vt`, `vn`) and validates every
//!    face exactly as the whole-file importer does (indices, NaN positions, counts against
//!    [`ImportLimits`]), so that pass 2 cannot fail on content;
//! 2. [`ObjVertices::for_each_triangle`] streams the faces again, fan-triangulated, as corners
//!    into the vertex arrays, with their material index.
//!
//! Meaning is the same as the `tobj` path (see the module docs of `import`): materials numbered
//! by first `usemtl` use, faces before any `usemtl` one past the last name; an attribute that
//! some face vertex lacks is dropped for the whole mesh; polylines and points are ignored.
//! `tobj` is not used here because it cannot stream. What the caller does with the triangles
//! (dropping degenerate ones, welding) is up to it.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use super::obj_syntax::{face, numbers, parse_error, position, record_material, usemtl_name, ForwardRefs};
use super::{
    check_triangle_count, check_vertex_count, unit_or_zero, ImportError, ImportErrorKind, ImportLimits, KindResult,
};
pub use crate::mesh::{Corner, NONE};

/// The vertex attributes of an OBJ file and what pass 1 learned about its faces.
#[derive(Debug, Default)]
pub struct ObjVertices {
    /// `v` lines (divided by `w` where given); all finite.
    pub positions: Vec<[f32; 3]>,
    /// `vt` lines (`u`, `v`; non-finite components become 0).
    pub uvs: Vec<[f32; 2]>,
    /// `vn` lines, unit length or zero.
    pub normals: Vec<[f32; 3]>,
    /// `usemtl` names in order of first use.
    pub material_names: Vec<String>,
    /// Triangles after fan triangulation.
    pub triangles: u64,
    /// Faces of one or two vertices (no triangle), counted with the degenerate ones dropped.
    pub short_faces: u64,
    /// Every face vertex has a texture coordinate (else UVs are dropped for the whole mesh).
    pub all_uvs: bool,
    /// Every face vertex has a normal.
    pub all_normals: bool,
}

impl ObjVertices {
    /// Pass 1 over the OBJ file at `path`.
    pub fn read(path: &Path, limits: &ImportLimits) -> Result<ObjVertices, ImportError> {
        Self::read_kind(path, limits).map_err(|kind| ImportError { path: path.to_path_buf(), kind })
    }

    fn read_kind(path: &Path, limits: &ImportLimits) -> KindResult<ObjVertices> {
        let mut out = ObjVertices { all_uvs: true, all_normals: true, ..Default::default() };
        let mut counts = [0u64; 3];
        let mut refs = ForwardRefs::default();
        let mut any_line = false;
        for_each_line(path, |line_no, line| {
            any_line = true;
            let mut words = line.split_whitespace();
            let Some(keyword) = words.next() else { return Ok(()) };
            match keyword {
                "v" => {
                    let p = position(words, line_no)?;
                    check_vertex_count(counts[0] + 1, limits)?;
                    out.positions.push(p);
                    counts[0] += 1;
                }
                "vt" => {
                    let c = numbers::<2>(&mut words, line_no, "vt")?;
                    out.uvs.push(c.map(|x| if x.is_finite() { x } else { 0.0 }));
                    counts[1] += 1;
                }
                "vn" => {
                    let c = numbers::<3>(&mut words, line_no, "vn")?;
                    out.normals.push(unit_or_zero(c));
                    counts[2] += 1;
                }
                "o" | "g" => refs.object(&counts)?,
                "usemtl" => {
                    record_material(&mut out.material_names, line, line_no)?;
                    refs.material(usemtl_name(line), &counts)?;
                }
                "f" => {
                    let mut corners = 0u64;
                    face(words, line_no, &counts, Some(&mut refs), |c| {
                        out.all_uvs &= c.vt != NONE;
                        out.all_normals &= c.vn != NONE;
                        corners += 1;
                    })?;
                    out.triangles += corners.saturating_sub(2);
                    out.short_faces += u64::from(corners < 3);
                    check_triangle_count(out.triangles, limits)?;
                }
                _ => {}
            }
            Ok(())
        })?;
        if !any_line {
            return Err(ImportErrorKind::EmptyFile);
        }
        refs.end(&counts)?;
        if out.triangles == 0 {
            return Err(ImportErrorKind::NoTriangles { degenerate_dropped: out.short_faces });
        }
        if !out.all_uvs {
            out.uvs = Vec::new();
        }
        if !out.all_normals {
            out.normals = Vec::new();
        }
        // The arrays grew by doubling: give the slack back (they stay for the whole bake).
        out.positions.shrink_to_fit();
        out.uvs.shrink_to_fit();
        out.normals.shrink_to_fit();
        Ok(out)
    }

    /// Pass 2: calls `f` with each triangle's corners (attributes dropped by pass 1 are
    /// [`NONE`]) and material index, in file order. The file must be the one pass 1 read.
    pub fn for_each_triangle(&self, path: &Path, mut f: impl FnMut([Corner; 3], u32)) -> Result<(), ImportError> {
        let unnamed = self.material_names.len() as u32;
        let mut material = unnamed;
        let mut counts = [0u64; 3];
        let mut corners: Vec<Corner> = Vec::new();
        let result = for_each_line(path, |line_no, line| {
            let mut words = line.split_whitespace();
            match words.next() {
                Some("v") => counts[0] += 1,
                Some("vt") => counts[1] += 1,
                Some("vn") => counts[2] += 1,
                Some("usemtl") => {
                    let name = usemtl_name(line);
                    material = self.material_names.iter().position(|n| n == name).map_or(unnamed, |m| m as u32);
                }
                Some("f") => {
                    corners.clear();
                    face(words, line_no, &counts, None, |mut c| {
                        if !self.all_uvs {
                            c.vt = NONE;
                        }
                        if !self.all_normals {
                            c.vn = NONE;
                        }
                        corners.push(c);
                    })?;
                    for k in 2..corners.len() {
                        f([corners[0], corners[k - 1], corners[k]], material);
                    }
                }
                _ => {}
            }
            Ok(())
        });
        result.map_err(|kind| ImportError { path: path.to_path_buf(), kind })
    }
}

/// The UTF-8 byte-order mark.
const BOM: &[u8] = "\u{feff}".as_bytes();

/// The `usemtl` names of the OBJ file at `path` in order of first use (a name's position is
/// its material index, as both OBJ readers number them), read line by line so that a large
/// file never has to fit in memory. Only `usemtl` lines are checked.
pub(crate) fn material_names(path: &Path) -> KindResult<Vec<String>> {
    let mut names = Vec::new();
    for_each_line(path, |line_no, line| {
        if line.split_whitespace().next() == Some("usemtl") {
            record_material(&mut names, line, line_no)?;
        }
        Ok(())
    })?;
    Ok(names)
}

/// Calls `f` with each line (1-based number, text without the line end) of the file.
fn for_each_line(path: &Path, mut f: impl FnMut(usize, &str) -> KindResult<()>) -> KindResult<()> {
    let file = File::open(path).map_err(ImportErrorKind::Io)?;
    let mut reader = BufReader::with_capacity(1 << 20, file);
    let mut buffer = Vec::new();
    let mut line_no = 0usize;
    loop {
        buffer.clear();
        if reader.read_until(b'\n', &mut buffer).map_err(ImportErrorKind::Io)? == 0 {
            return Ok(());
        }
        line_no += 1;
        if line_no == 1 && buffer.starts_with(BOM) {
            // One byte-order mark, blanked as the whole-file importer blanks it (so that
            // "\u{feff}usemtl" reads as "   usemtl" in both); a second one is part of the first
            // word, which makes the line one neither reader knows (both found by fuzzing).
            buffer[..BOM.len()].fill(b' ');
        }
        let line = std::str::from_utf8(&buffer)
            .map_err(|e| parse_error(line_no, &format!("not UTF-8 text (at byte {} of the line)", e.valid_up_to())))?;
        f(line_no, line)?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> tempfile_path::TempPath {
        tempfile_path::TempPath::with(text)
    }

    /// A file in the temp directory, removed on drop.
    mod tempfile_path {
        pub struct TempPath(pub std::path::PathBuf);
        impl TempPath {
            pub fn with(text: &str) -> TempPath {
                use std::sync::atomic::{AtomicU32, Ordering};
                static N: AtomicU32 = AtomicU32::new(0);
                let n = N.fetch_add(1, Ordering::Relaxed);
                let path = std::env::temp_dir().join(format!("mres-obj-stream-{}-{n}.obj", std::process::id()));
                std::fs::write(&path, text).unwrap();
                TempPath(path)
            }
        }
        impl Drop for TempPath {
            fn drop(&mut self) {
                let _ = std::fs::remove_file(&self.0);
            }
        }
    }

    #[test]
    fn fans_relative_indices_and_materials() {
        let file =
            write("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1 4/1\nusemtl b\nf -4/1 -2/-1 -1/1\n");
        let v = ObjVertices::read(&file.0, &ImportLimits::default()).unwrap();
        assert_eq!(v.triangles, 3);
        assert!(v.all_uvs && !v.all_normals);
        let mut tris = Vec::new();
        v.for_each_triangle(&file.0, |t, m| tris.push((t.map(|c| (c.v, c.vt, c.vn)), m))).unwrap();
        let n = NONE;
        assert_eq!(
            tris,
            vec![
                ([(0, 0, n), (1, 0, n), (2, 0, n)], 1),
                ([(0, 0, n), (2, 0, n), (3, 0, n)], 1),
                ([(0, 0, n), (2, 0, n), (3, 0, n)], 0),
            ]
        );
    }

    #[test]
    fn bad_files_are_errors_with_line_numbers() {
        for (text, expect) in [
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4"),
            ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "line 3"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "line 4"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "line 4"),
            ("v 0 0\n", "line 1"),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "no triangles"),
            ("v 0 0 0\nv 1 x 0\n", "line 2"),
        ] {
            let file = write(text);
            let err = ObjVertices::read(&file.0, &ImportLimits::default()).unwrap_err();
            assert!(err.to_string().contains(expect), "{text:?}: {err}");
            assert!(err.to_string().contains("mres-obj-stream"), "names the file: {err}");
        }
    }
}
