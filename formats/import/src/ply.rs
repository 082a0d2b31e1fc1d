//! PLY (Stanford polygon file) importer: ASCII, binary little endian and binary big endian.
//!
//! Hand-written rather than built on a crate. The maintained one, `ply-rs-bw` (the fork of
//! the original `ply-rs`), was read for this: it does not panic on bad input in the paths
//! we would use and caps its preallocations, but it keys elements and properties by name in
//! a map, so a header with two elements or properties of the same name silently loses one
//! and the binary layout of everything after it shifts (a misparse, not an error); its
//! errors carry no byte offset, its ASCII number grammar rejects `nan`, `.5` and `5.`, and it
//! hands every value to the element type through a name-keyed callback. The format itself
//! is small: a text header ([`header`]) and values read in declared order ([`body`]).
//!
//! What is read (see also the crate docs):
//! - `element vertex` with scalar `x y z` of any type and in any order; `nx ny nz` if all
//!   three are there; UVs from the first complete pair of `s t`, `u v`, `texture_u
//!   texture_v`. Other vertex properties, lists included, are skipped by their size.
//! - `element face` with a list `vertex_indices` (or `vertex_index`) of any integer types,
//!   fan-triangulated around its first index. Faces with fewer than three indices are
//!   skipped, as the OBJ importers skip `f` lines with fewer than three vertices; they are
//!   not counted as degenerate triangles. Other face properties (colours, per-corner
//!   `texcoord` lists) are skipped.
//! - Every other element is skipped (binary: by size, at once where it has no lists).
//! - All triangles get material 0: PLY has no materials.
//!
//! Hostile input: before anything is allocated, each element's declared count times the
//! fewest bytes one entry can take must fit in the bytes after the header, and the vertex
//! count must be within [`ImportLimits`]; the triangle count is checked face by face. Every
//! index is checked against the declared vertex count; positions must be finite after
//! conversion to `f32`. Errors name the header line, the body line (ASCII) or the byte offset
//! (binary) and the element entry. Data after the last element is an error.

mod body;
mod header;

use body::{list_count, Ascii, Binary, ReadResult, Values};
use header::{Element, Encoding, Header, PropertyType, Scalar};

use super::{check_triangle_count, check_vertex_count, ImportErrorKind, ImportLimits, KindResult, MeshBuilder};
use crate::SourceMesh;

/// What a vertex property is used for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    Position(usize),
    Normal(usize),
    Uv(usize),
    Skip,
}

/// Which elements and properties the mesh is read from.
#[derive(Debug)]
struct Plan {
    /// Index of the `vertex` element.
    vertex: usize,
    vertices: u64,
    /// One role per vertex property.
    roles: Vec<Role>,
    normals: bool,
    uvs: bool,
    /// Index of the `face` element and of its index list property.
    face: Option<(usize, usize)>,
}

/// UV property pairs, in order of preference.
const UV_NAMES: [[&str; 2]; 3] = [["s", "t"], ["u", "v"], ["texture_u", "texture_v"]];

impl Plan {
    fn new(header: &Header) -> KindResult<Plan> {
        let vertex = header
            .elements
            .iter()
            .position(|e| e.name == "vertex")
            .ok_or_else(|| header::header_error(header.lines, "the header declares no \"vertex\" element"))?;
        let element = &header.elements[vertex];
        let scalar = |name: &str| {
            element.property(name).filter(|&p| matches!(element.properties[p].ty, PropertyType::Scalar(_)))
        };
        let mut roles = vec![Role::Skip; element.properties.len()];
        for (k, name) in ["x", "y", "z"].into_iter().enumerate() {
            let p = scalar(name).ok_or_else(|| {
                header::header_error(element.line, &format!("element vertex has no scalar property {name:?}"))
            })?;
            roles[p] = Role::Position(k);
        }
        let normal = ["nx", "ny", "nz"].map(scalar);
        let normals = normal.iter().all(Option::is_some);
        if normals {
            normal.iter().flatten().enumerate().for_each(|(k, &p)| roles[p] = Role::Normal(k));
        }
        let uv = UV_NAMES.iter().map(|pair| pair.map(scalar)).find(|pair| pair.iter().all(Option::is_some));
        if let Some(uv) = uv {
            uv.iter().flatten().enumerate().for_each(|(k, &p)| roles[p] = Role::Uv(k));
        }
        let face = match header.elements.iter().position(|e| e.name == "face") {
            Some(f) => Some((f, face_list(&header.elements[f])?)),
            None => None,
        };
        Ok(Plan { vertex, vertices: element.count, roles, normals, uvs: uv.is_some(), face })
    }
}

/// The index of the face element's index list property.
fn face_list(face: &Element) -> KindResult<usize> {
    let list = face.property("vertex_indices").or_else(|| face.property("vertex_index")).ok_or_else(|| {
        header::header_error(face.line, "element face has no \"vertex_indices\" or \"vertex_index\" property")
    })?;
    match face.properties[list].ty {
        PropertyType::List { item, .. } if item.is_integer() => Ok(list),
        _ => {
            let message = format!("face property {:?} is not a list of integers", face.properties[list].name);
            Err(header::header_error(face.line, &message))
        }
    }
}

/// Imports a PLY file; `bytes` is the whole file (not empty, already size-checked).
pub(super) fn import(bytes: &[u8], limits: &ImportLimits) -> KindResult<SourceMesh> {
    let header = header::parse(bytes)?;
    let plan = Plan::new(&header)?;
    check_sizes(&header, bytes.len() - header.body_start)?;
    check_vertex_count(plan.vertices, limits)?;
    let body = &bytes[header.body_start..];
    match header.encoding {
        Encoding::Ascii => read(&mut Ascii::new(body, header.lines + 1), &header, &plan, limits),
        Encoding::BinaryLittleEndian => {
            read(&mut Binary::<false>::new(body, header.body_start), &header, &plan, limits)
        }
        Encoding::BinaryBigEndian => read(&mut Binary::<true>::new(body, header.body_start), &header, &plan, limits),
    }
}

/// PLY files reference no other files; the header is parsed so that a non-PLY file is an error.
pub(super) fn referenced_files(bytes: &[u8]) -> KindResult<Vec<std::path::PathBuf>> {
    header::parse(bytes)?;
    Ok(Vec::new())
}

/// Fails if the elements' declared counts cannot fit in the `body` bytes, so that no count is
/// trusted further than the file's size (capacities below are bounded by it).
fn check_sizes(header: &Header, body: usize) -> KindResult<()> {
    // An ASCII file may end without a line break after its last value.
    let available = body as u64 + u64::from(header.encoding == Encoding::Ascii);
    let mut needed = 0u64;
    for element in &header.elements {
        needed = element
            .count
            .checked_mul(element.min_entry_bytes(header.encoding))
            .and_then(|n| n.checked_add(needed))
            .unwrap_or(u64::MAX);
        if needed > available {
            let message = format!(
                "element {} declares {} entries, more than the {body} bytes after the header can hold (truncated?)",
                element.name, element.count
            );
            return Err(header::header_error(element.line, &message));
        }
    }
    Ok(())
}

/// A parse error at the current position of `values`, in entry `index` of `element`.
fn fail(values: &impl Values, element: &Element, index: u64, message: String) -> ImportErrorKind {
    ImportErrorKind::Parse(format!("{}: {} {index}: {message}", values.at(), element.name))
}

/// Reads the body: every element in file order, then checks that nothing follows.
fn read(values: &mut impl Values, header: &Header, plan: &Plan, limits: &ImportLimits) -> KindResult<SourceMesh> {
    let triangle_hint = match plan.face {
        Some((f, list)) => triangle_hint(&header.elements[f], list, header.encoding, values.body_len(), limits),
        None => 0,
    };
    let mut builder = MeshBuilder::new(plan.normals, plan.uvs, plan.vertices as usize, triangle_hint);
    // Triangles of a face element that comes before the vertex element wait for the vertices
    // (the builder needs their positions to drop degenerate triangles).
    let mut pending: Vec<[u32; 3]> = Vec::new();
    let mut triangles = 0u64;
    for (index, element) in header.elements.iter().enumerate() {
        if index == plan.vertex {
            read_vertices(values, element, &plan.roles, &mut builder)?;
        } else if let Some((_, list)) = plan.face.filter(|&(f, _)| f == index) {
            let faces = Faces { element, list, vertices: plan.vertices, limits };
            if index < plan.vertex {
                faces.read(values, &mut triangles, &mut |t| pending.push(t))?;
            } else {
                faces.read(values, &mut triangles, &mut |t| builder.push_triangle(t, 0))?;
            }
        } else {
            skip_element(values, element)?;
        }
    }
    values.finish().map_err(|m| ImportErrorKind::Parse(format!("{}: {m}", values.at())))?;
    for triangle in pending {
        builder.push_triangle(triangle, 0);
    }
    builder.finish()
}

/// Capacity for the triangles of `face`: its count, but no more than the limit, nor than
/// the `body` bytes could hold if every face were a triangle (so that empty faces reserve
/// nothing).
fn triangle_hint(face: &Element, list: usize, encoding: Encoding, body: usize, limits: &ImportLimits) -> usize {
    let item = match face.properties[list].ty {
        PropertyType::List { item, .. } => item.size() as u64,
        PropertyType::Scalar(_) => 0,
    };
    let per_triangle = face.min_entry_bytes(encoding) + if encoding == Encoding::Ascii { 6 } else { 3 * item };
    face.count.min(limits.max_triangles).min(body as u64 / per_triangle.max(1)) as usize
}

fn read_vertices(
    values: &mut impl Values,
    element: &Element,
    roles: &[Role],
    builder: &mut MeshBuilder,
) -> KindResult<()> {
    for i in 0..element.count {
        let (position, normal, uv) = read_vertex(values, element, roles).map_err(|m| fail(values, element, i, m))?;
        if !position.iter().all(|c| c.is_finite()) {
            return Err(ImportErrorKind::NonFinitePosition(format!(
                "{}: vertex {i}: {position:?} (as 32-bit floats)",
                values.entry_at()
            )));
        }
        builder.push_vertex(position, normal, uv);
    }
    Ok(())
}

type Vertex = ([f32; 3], [f32; 3], [f32; 2]);

fn read_vertex(values: &mut impl Values, element: &Element, roles: &[Role]) -> ReadResult<Vertex> {
    let (mut position, mut normal, mut uv) = ([0f32; 3], [0f32; 3], [0f32; 2]);
    values.begin()?;
    for (property, &role) in element.properties.iter().zip(roles) {
        match (property.ty, role) {
            (PropertyType::Scalar(ty), Role::Skip) => values.skip(ty, 1)?,
            (PropertyType::Scalar(ty), Role::Position(k)) => position[k] = values.value(ty)? as f32,
            (PropertyType::Scalar(ty), Role::Normal(k)) => normal[k] = values.value(ty)? as f32,
            (PropertyType::Scalar(ty), Role::Uv(k)) => uv[k] = values.value(ty)? as f32,
            (PropertyType::List { count, item }, _) => skip_list(values, count, item)?,
        }
    }
    values.end()?;
    Ok((position, normal, uv))
}

fn skip_list(values: &mut impl Values, count: Scalar, item: Scalar) -> ReadResult<()> {
    let n = list_count(values, count)?;
    values.skip(item, n)
}

/// Skips every entry of an element the mesh does not use.
fn skip_element(values: &mut impl Values, element: &Element) -> KindResult<()> {
    if element.properties.is_empty() {
        return Ok(());
    }
    if let Some(size) = element.fixed_binary_size() {
        if let Some(result) = values.skip_entries(element.count, size) {
            return result.map_err(|m| fail(values, element, 0, format!("skipping {} entries: {m}", element.count)));
        }
    }
    for i in 0..element.count {
        skip_entry(values, element).map_err(|m| fail(values, element, i, m))?;
    }
    Ok(())
}

fn skip_entry(values: &mut impl Values, element: &Element) -> ReadResult<()> {
    values.begin()?;
    for property in &element.properties {
        match property.ty {
            PropertyType::Scalar(ty) => values.skip(ty, 1)?,
            PropertyType::List { count, item } => skip_list(values, count, item)?,
        }
    }
    values.end()
}

/// The face element and what its indices are checked against.
struct Faces<'a> {
    element: &'a Element,
    /// Index of the index list among the element's properties.
    list: usize,
    vertices: u64,
    limits: &'a ImportLimits,
}

impl Faces<'_> {
    /// Reads every face, passing its fan triangles to `sink`; `triangles` counts them.
    fn read(&self, values: &mut impl Values, triangles: &mut u64, sink: &mut dyn FnMut([u32; 3])) -> KindResult<()> {
        for i in 0..self.element.count {
            values.begin().map_err(|m| fail(values, self.element, i, m))?;
            for (k, property) in self.element.properties.iter().enumerate() {
                match property.ty {
                    PropertyType::List { count, item } if k == self.list => {
                        self.read_face(values, i, count, item, triangles, sink)?;
                    }
                    PropertyType::List { count, item } => {
                        skip_list(values, count, item).map_err(|m| fail(values, self.element, i, m))?;
                    }
                    PropertyType::Scalar(ty) => values.skip(ty, 1).map_err(|m| fail(values, self.element, i, m))?,
                }
            }
            values.end().map_err(|m| fail(values, self.element, i, m))?;
        }
        Ok(())
    }

    /// Reads the index list of face `i` and emits its fan, streaming (no list is buffered).
    fn read_face(
        &self,
        values: &mut impl Values,
        i: u64,
        count: Scalar,
        item: Scalar,
        triangles: &mut u64,
        sink: &mut dyn FnMut([u32; 3]),
    ) -> KindResult<()> {
        let n = list_count(values, count).map_err(|m| fail(values, self.element, i, m))?;
        if n < 3 {
            return values.skip(item, n).map_err(|m| fail(values, self.element, i, m));
        }
        *triangles += n - 2;
        check_triangle_count(*triangles, self.limits)?;
        let first = self.index(values, i, item)?;
        let mut previous = self.index(values, i, item)?;
        for _ in 2..n {
            let next = self.index(values, i, item)?;
            sink([first, previous, next]);
            previous = next;
        }
        Ok(())
    }

    fn index(&self, values: &mut impl Values, i: u64, item: Scalar) -> KindResult<u32> {
        let v = values.value(item).map_err(|m| fail(values, self.element, i, m))?;
        if v < 0.0 || v >= self.vertices as f64 {
            return Err(ImportErrorKind::IndexOutOfRange {
                what: format!("{}: face {i}: vertex", values.at()),
                index: v as i64,
                count: self.vertices,
            });
        }
        Ok(v as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn import_str(text: &str) -> KindResult<SourceMesh> {
        import(text.as_bytes(), &ImportLimits::default())
    }

    const HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                        property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    const VERTICES: &str = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n";

    #[test]
    fn quad_is_a_fan() {
        let mesh = import_str(&format!("{HEAD}{VERTICES}4 0 1 2 3\n")).unwrap();
        assert_eq!(mesh.indices, vec![0, 1, 2, 0, 2, 3]);
        assert_eq!(mesh.materials, vec![0, 0]);
    }

    #[test]
    fn short_faces_are_skipped_and_degenerates_counted() {
        let head = HEAD.replace("face 1", "face 3");
        let mesh = import_str(&format!("{head}{VERTICES}2 0 1\n3 0 0 1\n3 0 1 2\n")).unwrap();
        assert_eq!(mesh.indices, vec![0, 1, 2]);
        assert_eq!(mesh.degenerate_dropped, 1);
    }

    #[test]
    fn errors_name_line_and_entry() {
        for (body, expect) in [
            ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 4\n", "line 14: face 0: vertex index 4 is out of range (4 available)"),
            ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 -1\n", "line 14: face 0: vertex index -1"),
            ("0 0 0\n1 0 0\nnan 1 0\n0 1 0\n3 0 1 2\n", "line 12: vertex 2: [NaN, 1.0, 0.0]"),
            ("0 0 0\n1 0 0\n1 1e39 0\n0 1 0\n3 0 1 2\n", "line 12: vertex 2"),
            ("0 0 0\n1 0 0\n1 1 0 7\n0 1 0\n3 0 1 2\n", "line 12: vertex 2: more values"),
            ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1\n", "line 14: face 0: fewer values"),
            ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n1 2 3\n", "line 15: data after the last element"),
            ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n", "line 7: element face declares 1 entries, more than the 24 bytes"),
            ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n\n\n\n\n", "line 18: face 0: the file ends here"),
            ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2.5\n", "line 14: face 0: \"2.5\" is not a valid int value"),
        ] {
            let err = import_str(&format!("{HEAD}{body}")).unwrap_err().to_string();
            assert!(err.contains(expect), "{body:?}: {err}");
        }
    }

    #[test]
    fn declared_counts_must_fit_the_file() {
        let head = HEAD.replace("vertex 4", "vertex 4000000000");
        let err = import_str(&format!("{head}{VERTICES}")).unwrap_err().to_string();
        assert!(err.contains("line 3: element vertex declares 4000000000 entries"), "{err}");
        let limits = ImportLimits { max_triangles: 1, ..ImportLimits::default() };
        let err = import(format!("{HEAD}{VERTICES}4 0 1 2 3\n").as_bytes(), &limits).unwrap_err();
        assert!(matches!(err, ImportErrorKind::TooLarge(_)), "{err}");
    }

    #[test]
    fn header_requirements() {
        let no_z = HEAD.replace("property float z\n", "");
        assert!(import_str(&no_z)
            .unwrap_err()
            .to_string()
            .contains("line 3: element vertex has no scalar property \"z\""));
        let float_indices = HEAD.replace("uchar int", "uchar float");
        let err = import_str(&float_indices).unwrap_err().to_string();
        assert!(err.contains("line 7: face property \"vertex_indices\" is not a list of integers"), "{err}");
        let no_vertex = "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n";
        assert!(import_str(no_vertex).unwrap_err().to_string().contains("no \"vertex\" element"));
    }
}
