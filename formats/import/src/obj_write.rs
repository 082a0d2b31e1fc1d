//! A minimal OBJ writer, so that any tool can inspect a mesh or a cut mres produced.

use crate::SourceMesh;
use std::io::{self, Write};

/// Writes `mesh` as OBJ text: `v`, optional `vn`/`vt`, and `f` with 1-based indices; a
/// `usemtl mN` line wherever the material changes.
pub fn write_obj(mesh: &SourceMesh, out: &mut impl Write) -> io::Result<()> {
    write_obj_named(mesh, &[], out)
}

/// [`write_obj`] with material names: `usemtl <name>` for material `N` where `names[N]` is a
/// name (line breaks become spaces, so the name stays one line), else `usemtl mN`.
pub fn write_obj_named(mesh: &SourceMesh, names: &[Option<String>], out: &mut impl Write) -> io::Result<()> {
    writeln!(out, "# written by mres")?;
    for p in &mesh.positions {
        writeln!(out, "v {} {} {}", p[0], p[1], p[2])?;
    }
    if let Some(normals) = &mesh.normals {
        for n in normals {
            writeln!(out, "vn {} {} {}", n[0], n[1], n[2])?;
        }
    }
    if let Some(uvs) = &mesh.uvs {
        for t in uvs {
            writeln!(out, "vt {} {}", t[0], t[1])?;
        }
    }
    let mut material = None;
    for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
        let m = mesh.materials.get(t).copied().unwrap_or(0);
        if material != Some(m) {
            match names.get(m as usize).and_then(|n| n.as_deref()).map(str::trim).filter(|n| !n.is_empty()) {
                Some(name) => writeln!(out, "usemtl {}", name.replace(['\n', '\r'], " "))?,
                None => writeln!(out, "usemtl m{m}")?,
            }
            material = Some(m);
        }
        let corner = |i: u32| {
            let i = i + 1;
            match (mesh.uvs.is_some(), mesh.normals.is_some()) {
                (true, true) => format!("{i}/{i}/{i}"),
                (true, false) => format!("{i}/{i}"),
                (false, true) => format!("{i}//{i}"),
                (false, false) => format!("{i}"),
            }
        };
        writeln!(out, "f {} {} {}", corner(tri[0]), corner(tri[1]), corner(tri[2]))?;
    }
    Ok(())
}
