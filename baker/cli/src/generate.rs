//! Generated test meshes: a closed cube-sphere, an open terrain, a field of disconnected boxes.
//! Used by tests, benchmarks and `mres generate`.

use mres_import::SourceMesh;

/// A closed sphere of radius 1 made from a cube with `n`×`n` quads per face (12·n² triangles),
/// with normals. Vertices on cube edges are generated once, so the mesh is watertight.
pub fn sphere(n: u32) -> SourceMesh {
    let n = n.max(1) as i32;
    let mut index_of = std::collections::HashMap::new();
    let mut positions = Vec::new();
    let mut vertex = |p: [i32; 3]| -> u32 {
        *index_of.entry(p).or_insert_with(|| {
            let v = [p[0] as f32 / n as f32, p[1] as f32 / n as f32, p[2] as f32 / n as f32];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            positions.push([v[0] / l, v[1] / l, v[2] / l]);
            positions.len() as u32 - 1
        })
    };
    let mut indices = Vec::new();
    for axis in 0..3 {
        for side in [-n, n] {
            for i in 0..n {
                for j in 0..n {
                    let at = |a: i32, b: i32| {
                        let mut p = [0; 3];
                        p[axis] = side;
                        p[(axis + 1) % 3] = -n + 2 * a;
                        p[(axis + 2) % 3] = -n + 2 * b;
                        p
                    };
                    let (i, j) = (i, j);
                    let q = [vertex(at(i, j)), vertex(at(i + 1, j)), vertex(at(i + 1, j + 1)), vertex(at(i, j + 1))];
                    // Outward winding on both sides.
                    if side > 0 {
                        indices.extend_from_slice(&[q[0], q[1], q[2], q[0], q[2], q[3]]);
                    } else {
                        indices.extend_from_slice(&[q[0], q[2], q[1], q[0], q[3], q[2]]);
                    }
                }
            }
        }
    }
    let normals = positions.clone();
    SourceMesh { normals: Some(normals), ..SourceMesh::positions_only(positions, indices) }
}

/// The cube-sphere of [`sphere`] with every cube face a separate UV chart and material: the
/// vertices along the 12 cube edges are duplicated with different UVs (attribute seams), so the
/// mesh is watertight by position only. 12·n² triangles, 6 materials.
pub fn seamed_sphere(n: u32) -> SourceMesh {
    let n = n.max(1) as i32;
    let (mut positions, mut uvs, mut indices, mut materials) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for face in 0..6 {
        let (axis, side) = (face / 2, if face % 2 == 0 { -n } else { n });
        let base = positions.len() as u32;
        for a in 0..=n {
            for b in 0..=n {
                let mut p = [0i32; 3];
                p[axis] = side;
                p[(axis + 1) % 3] = -n + 2 * a;
                p[(axis + 2) % 3] = -n + 2 * b;
                let v = p.map(|c| c as f32 / n as f32);
                let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                positions.push([v[0] / l, v[1] / l, v[2] / l]);
                uvs.push([a as f32 / n as f32, b as f32 / n as f32]);
            }
        }
        let at = |a: i32, b: i32| base + (a * (n + 1) + b) as u32;
        for a in 0..n {
            for b in 0..n {
                let q = [at(a, b), at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)];
                if side > 0 {
                    indices.extend_from_slice(&[q[0], q[1], q[2], q[0], q[2], q[3]]);
                } else {
                    indices.extend_from_slice(&[q[0], q[2], q[1], q[0], q[3], q[2]]);
                }
                materials.extend_from_slice(&[face as u32; 2]);
            }
        }
    }
    let normals = positions.clone();
    SourceMesh { positions, normals: Some(normals), uvs: Some(uvs), indices, materials, degenerate_dropped: 0 }
}

/// An open height-field terrain of `n`×`n` quads (2·n² triangles) over [0, 1]², with UVs.
pub fn terrain(n: u32) -> SourceMesh {
    let n = n.max(1);
    let mut positions = Vec::with_capacity(((n + 1) * (n + 1)) as usize);
    let mut uvs = Vec::with_capacity(positions.capacity());
    for y in 0..=n {
        for x in 0..=n {
            let (u, v) = (x as f32 / n as f32, y as f32 / n as f32);
            let h = 0.08 * (u * 9.0).sin() * (v * 7.0).cos()
                + 0.03 * (u * 31.0 + v * 17.0).sin()
                + 0.01 * (u * 97.0).cos() * (v * 83.0).sin();
            positions.push([u, h, v]);
            uvs.push([u, v]);
        }
    }
    let row = n + 1;
    let mut indices = Vec::with_capacity((n * n * 6) as usize);
    for y in 0..n {
        for x in 0..n {
            let i = y * row + x;
            indices.extend_from_slice(&[i, i + row, i + 1, i + 1, i + row, i + row + 1]);
        }
    }
    SourceMesh { uvs: Some(uvs), ..SourceMesh::positions_only(positions, indices) }
}

/// `count` disconnected closed boxes on a square grid, each face split into `k`×`k` quads
/// (12·k² triangles per box; k = 4 gives 192).
pub fn boxes(count: u32, k: u32) -> SourceMesh {
    let unit = sphere_free_box(k.max(1));
    let side = (count as f32).sqrt().ceil() as u32;
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for b in 0..count {
        let (gx, gz) = ((b % side) as f32 * 2.0, (b / side) as f32 * 2.0);
        let scale = 0.6 + 0.3 * ((b * 7919) % 13) as f32 / 13.0;
        let base = positions.len() as u32;
        positions.extend(unit.positions.iter().map(|p| [gx + p[0] * scale, p[1] * scale, gz + p[2] * scale]));
        indices.extend(unit.indices.iter().map(|i| base + i));
    }
    SourceMesh::positions_only(positions, indices)
}

/// A closed unit box from −0.5 to 0.5 with `k`×`k` quads per face.
fn sphere_free_box(k: u32) -> SourceMesh {
    let cube = sphere(k);
    // Project the cube-sphere back onto the cube: same topology, flat faces.
    let positions = cube
        .positions
        .iter()
        .map(|p| {
            let m = p[0].abs().max(p[1].abs()).max(p[2].abs());
            [p[0] / m * 0.5, p[1] / m * 0.5, p[2] / m * 0.5]
        })
        .collect();
    SourceMesh::positions_only(positions, cube.indices)
}

/// Foliage-like aggregate geometry: `count` disconnected two-triangle cards (open quads) of
/// random size and orientation in a unit cube (deterministic).
pub fn cards(count: u32) -> SourceMesh {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f32 / (1u64 << 53) as f32
    };
    let (mut positions, mut indices) = (Vec::new(), Vec::new());
    for _ in 0..count {
        let c = [next(), next(), next()];
        let s = 0.01 + 0.03 * next();
        let (a, b) = (next() * std::f32::consts::TAU, next() * std::f32::consts::PI);
        let u = [a.cos() * s, a.sin() * s, 0.0];
        let v = [0.0, b.cos() * s, b.sin() * s];
        let base = positions.len() as u32;
        for (du, dv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            positions.push([0, 1, 2].map(|k| c[k] + du * u[k] + dv * v[k]));
        }
        indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    SourceMesh::positions_only(positions, indices)
}

/// An open multi-part scene like an architecture kit: `count` rooms on a square grid, each a
/// floor and four one-sided walls facing inwards (8×8 quads each, no ceiling), two walls with a
/// window hole of 2×2 quads, an open crate (a box without its lid, facing outwards, 4×4 quads a
/// side) on the floor, and six two-triangle cards leaning in the room. 796 triangles per room.
/// Seen from outside, the walls' backs, the inside of the crate and the cards' backs are the
/// surface itself seen from behind.
pub fn rooms(count: u32) -> SourceMesh {
    let side = (count as f32).sqrt().ceil().max(1.0) as u32;
    let mut mesh = SourceMesh::positions_only(Vec::new(), Vec::new());
    let mut quads = |o: [f32; 3], du: [f32; 3], dv: [f32; 3], k: u32, hole: &dyn Fn(u32, u32) -> bool| {
        panel(&mut mesh, (o, du, dv), (k, k), hole);
    };
    let solid = |_: u32, _: u32| false;
    let window = |i: u32, j: u32| (3..5).contains(&i) && (3..5).contains(&j);
    let (w, h) = (4.0f32, 3.0f32);
    for r in 0..count {
        let (x, z) = ((r % side) as f32 * (w + 1.0), (r / side) as f32 * (w + 1.0));
        let p = |dx: f32, dy: f32, dz: f32| [x + dx, dy, z + dz];
        quads(p(0.0, 0.0, 0.0), [0.0, 0.0, w], [w, 0.0, 0.0], 8, &solid);
        quads(p(0.0, 0.0, 0.0), [w, 0.0, 0.0], [0.0, h, 0.0], 8, &window);
        quads(p(w, 0.0, w), [-w, 0.0, 0.0], [0.0, h, 0.0], 8, &solid);
        quads(p(0.0, 0.0, w), [0.0, 0.0, -w], [0.0, h, 0.0], 8, &window);
        quads(p(w, 0.0, 0.0), [0.0, 0.0, w], [0.0, h, 0.0], 8, &solid);
        // The crate: four sides and a bottom facing outwards, open at the top.
        let (c, s) = (p(1.0, 0.0, 1.2), 0.8 + 0.1 * (r % 4) as f32);
        let q = |dx: f32, dy: f32, dz: f32| [c[0] + dx * s, c[1] + dy * s, c[2] + dz * s];
        quads(q(0.0, 0.0, 0.0), [0.0, s, 0.0], [s, 0.0, 0.0], 4, &solid);
        quads(q(1.0, 0.0, 1.0), [0.0, s, 0.0], [-s, 0.0, 0.0], 4, &solid);
        quads(q(0.0, 0.0, 1.0), [0.0, s, 0.0], [0.0, 0.0, -s], 4, &solid);
        quads(q(1.0, 0.0, 0.0), [0.0, s, 0.0], [0.0, 0.0, s], 4, &solid);
        quads(q(0.0, 0.0, 0.0), [s, 0.0, 0.0], [0.0, 0.0, s], 4, &solid);
        for k in 0..6 {
            let a = k as f32 * 1.1 + r as f32 * 0.37;
            let base = p(2.2 + 0.25 * k as f32, 0.0, 0.6 + 0.5 * k as f32);
            quads(base, [0.5 * a.cos(), 0.0, 0.5 * a.sin()], [0.1, 0.9, 0.05], 1, &solid);
        }
    }
    mesh
}

/// Appends to `mesh` a grid of `cols` × `rows` quads spanning `du` × `dv` from `o`, two
/// triangles each, counter-clockwise seen from the side du × dv points to, without the quads
/// (column, row) that `hole` names; the positions on a 1/1024 grid, so that sheets meant to
/// meet share their vertices exactly.
pub fn panel(
    mesh: &mut SourceMesh,
    (o, du, dv): ([f32; 3], [f32; 3], [f32; 3]),
    (cols, rows): (u32, u32),
    hole: &dyn Fn(u32, u32) -> bool,
) {
    let base = mesh.positions.len() as u32;
    for j in 0..=rows {
        for i in 0..=cols {
            let (a, b) = (i as f32 / cols as f32, j as f32 / rows as f32);
            mesh.positions.push([0, 1, 2].map(|c| ((o[c] + a * du[c] + b * dv[c]) * 1024.0).round() / 1024.0));
        }
    }
    let at = |i: u32, j: u32| base + j * (cols + 1) + i;
    for j in 0..rows {
        for i in (0..cols).filter(|&i| !hole(i, j)) {
            let quad = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j), at(i + 1, j + 1), at(i, j + 1)];
            mesh.indices.extend_from_slice(&quad);
            mesh.materials.extend_from_slice(&[0, 0]);
        }
    }
}

/// Walls standing inside a floor, as an architecture model welded into one mesh: a 10 × 10
/// floor of `n` × `n` quads and two 10 × 5 walls of `n` × `n / 2` quads standing on its middle
/// lines and crossing each other (`n` even), all on a 1/1024 grid so that they share their
/// vertices. Each edge of a wall's foot is used by three triangles (two of the floor, one of the
/// wall), each edge of the line where the walls cross by four: non-manifold edges everywhere
/// the parts meet. 4·N² triangles.
pub fn walls(n: u32) -> SourceMesh {
    let n = n.max(2) & !1;
    let mut mesh = SourceMesh::positions_only(Vec::new(), Vec::new());
    let solid = |_: u32, _: u32| false;
    panel(&mut mesh, ([0.0; 3], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]), (n, n), &solid);
    panel(&mut mesh, ([0.0, 5.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.0, 5.0]), (n, n / 2), &solid);
    panel(&mut mesh, ([5.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 5.0]), (n, n / 2), &solid);
    mesh
}

/// The cube-sphere with defects real scans and CAD exports have: every 97th triangle removed
/// (holes), every 89th duplicated, and a fin of two triangles on one edge per 1,000 triangles
/// (non-manifold edges used three times).
pub fn defects(n: u32) -> SourceMesh {
    let base = sphere(n);
    let mut positions = base.positions.clone();
    let mut indices = Vec::new();
    for (t, tri) in base.indices.chunks_exact(3).enumerate() {
        if t % 97 == 13 {
            continue;
        }
        indices.extend_from_slice(tri);
        if t % 89 == 7 {
            indices.extend_from_slice(tri);
        }
        if t % 1000 == 500 {
            // A fin standing on the edge tri[0]-tri[1].
            let (a, b) = (positions[tri[0] as usize], positions[tri[1] as usize]);
            let tip = [0, 1, 2].map(|k| (a[k] + b[k]) * 0.5 * 1.05);
            positions.push(tip);
            indices.extend_from_slice(&[tri[0], tri[1], positions.len() as u32 - 1]);
        }
    }
    SourceMesh::positions_only(positions, indices)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_sizes() {
        assert_eq!(sphere(10).triangle_count(), 1200);
        assert_eq!(terrain(10).triangle_count(), 200);
        assert_eq!(boxes(16, 4).triangle_count(), 16 * 192);
        let seamed = seamed_sphere(10);
        assert_eq!(seamed.triangle_count(), 1200);
        assert_eq!(seamed.positions.len(), 6 * 121);
        assert_eq!(rooms(3).triangle_count(), 3 * 796);
        assert_eq!(walls(10).triangle_count(), 4 * 100);
    }

    #[test]
    fn walls_meet_the_floor_and_each_other_on_non_manifold_edges() {
        let uses = edge_uses(&walls(8));
        let used = |n: u32| uses.values().filter(|&&u| u == n).count();
        // Two feet of 8 edges (three triangles each), and the crossing line of 4 (four each).
        assert_eq!((used(3), used(4)), (16, 4));
    }

    /// How many triangles use each edge, edges by position.
    fn edge_uses(m: &SourceMesh) -> std::collections::HashMap<([u32; 3], [u32; 3]), u32> {
        let key = |i: u32| m.positions[i as usize].map(f32::to_bits);
        let mut uses = std::collections::HashMap::new();
        for t in m.indices.chunks_exact(3) {
            for e in 0..3 {
                let (a, b) = (key(t[e]), key(t[(e + 1) % 3]));
                *uses.entry(if a < b { (a, b) } else { (b, a) }).or_insert(0) += 1;
            }
        }
        uses
    }

    /// Edges used by exactly one triangle (open borders), by position.
    fn open_edges(m: &SourceMesh) -> usize {
        edge_uses(m).values().filter(|&&n| n == 1).count()
    }

    #[test]
    fn rooms_are_open_with_window_holes_and_face_inwards() {
        let m = rooms(1);
        // By position the floor and the walls are one open box and the crate another: open
        // are the walls' top rims (4 × 8 edges), the two windows (8 each), the crate's rim
        // (4 × 4) and the cards' outlines (4 each).
        assert_eq!(open_edges(&m), 4 * 8 + 2 * 8 + 4 * 4 + 6 * 4);
        // The floor faces up and the first wall (z = 0) faces +z, into the room.
        let normal = |t: usize| {
            let p = |k: usize| m.positions[m.indices[3 * t + k] as usize];
            let (a, b, c) = (p(0), p(1), p(2));
            let (u, v) = ([0, 1, 2].map(|i| b[i] - a[i]), [0, 1, 2].map(|i| c[i] - a[i]));
            [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
        };
        assert!(normal(0)[1] > 0.0);
        assert!(normal(128)[2] > 0.0);
    }
}
