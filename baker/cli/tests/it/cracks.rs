//! The validator's crack check (docs/INVARIANTS.md §1) still catches every crack now that open
//! borders simplify: a valid bake of an open terrain is taken apart into its DAG, broken in one
//! way (a dropped cluster, a hole, a T-junction, a wrongly set or cleared open-border mark),
//! written again and validated. Each must fail, naming the broken rule; the unbroken DAG,
//! written the same way, must pass.

use mres_build::bake::bake;
use mres_build::BakeSettings;
use mres_check::validate::{validate, ValidateOptions};
use mres_cli::generate;
use mres_format::{write_mres, Dag, DagCluster, MresFile, NO_GROUP};

/// A baked open terrain as a writable DAG.
fn terrain_dag() -> Dag {
    let bytes = bake(generate::terrain(40), &BakeSettings::default(), &|_| {}).expect("bake").bytes;
    let file = MresFile::parse(bytes).expect("parses");
    let decoded = file.decode_all().expect("decodes");
    let clusters = decoded.into_iter().zip(&file.clusters).map(|(d, info)| DagCluster::from_decoded(d, info)).collect();
    Dag { header: file.header, groups: file.groups.clone(), clusters }
}

/// The validator's violations for `dag`, written and read back.
fn violations(dag: &Dag) -> Vec<String> {
    let file = MresFile::parse(write_mres(dag, 3).expect("writes")).expect("parses");
    let options = ValidateOptions { random_cuts: 50, ..Default::default() };
    validate(&file, &options).expect("decodes").violations
}

fn assert_caught(dag: &Dag, rule: &str) {
    let v = violations(dag);
    assert!(v.iter().any(|m| m.contains(rule)), "expected a '{rule}' violation, got {v:#?}");
}

/// Index of a level-0 cluster, and within it a triangle none of whose edges is marked.
fn interior_triangle(dag: &Dag) -> (usize, usize) {
    for (c, cluster) in dag.clusters.iter().enumerate() {
        if cluster.own_group != NO_GROUP || cluster.indices.len() < 3 * 64 {
            continue;
        }
        if let Some(t) = (0..cluster.indices.len() / 3).find(|&t| cluster.open_edges.get(t).copied().unwrap_or(0) == 0)
        {
            return (c, t);
        }
    }
    panic!("no level-0 cluster with an unmarked triangle");
}

#[test]
fn the_unbroken_dag_passes() {
    let v = violations(&terrain_dag());
    assert!(v.is_empty(), "{v:#?}");
}

#[test]
fn a_dropped_cluster_is_caught() {
    let mut dag = terrain_dag();
    let (c, _) = interior_triangle(&dag);
    dag.clusters.remove(c);
    assert_caught(&dag, "crack-free cuts");
}

#[test]
fn a_hole_is_caught() {
    let mut dag = terrain_dag();
    let (c, t) = interior_triangle(&dag);
    let cluster = &mut dag.clusters[c];
    cluster.indices.drain(3 * t..3 * t + 3);
    cluster.open_edges.remove(t);
    assert_caught(&dag, "crack-free cuts");
}

#[test]
fn a_t_junction_is_caught() {
    let mut dag = terrain_dag();
    // A cluster above level 0 with room for one more vertex and triangle: split one triangle
    // at the midpoint of its first edge, which its neighbour keeps whole.
    let c = dag
        .clusters
        .iter()
        .position(|k| k.own_group != NO_GROUP && k.indices.len() < 3 * 128 && k.positions.len() < 255)
        .expect("a cluster with room");
    let cluster = &mut dag.clusters[c];
    let (a, b, x) = (cluster.indices[0], cluster.indices[1], cluster.indices[2]);
    let (pa, pb) = (cluster.positions[a as usize], cluster.positions[b as usize]);
    cluster.positions.push([0, 1, 2].map(|k| (pa[k] + pb[k]) / 2));
    if !cluster.normals.is_empty() {
        cluster.normals.push(cluster.normals[a as usize]);
    }
    if !cluster.uvs.is_empty() {
        cluster.uvs.push(cluster.uvs[a as usize]);
    }
    let m = cluster.positions.len() as u8 - 1;
    cluster.indices[1] = m;
    cluster.indices.extend_from_slice(&[m, b, x]);
    if !cluster.materials.is_empty() {
        cluster.materials.push(cluster.materials[0]);
    }
    let mask = cluster.open_edges[0];
    // Both halves keep the marks of the edges they inherit (a-x on the first, b-x on the second).
    cluster.open_edges[0] = mask & 0b100;
    cluster.open_edges.push(mask & 0b010);
    assert_caught(&dag, "crack-free cuts");
}

#[test]
fn a_wrongly_set_mark_is_caught() {
    let mut dag = terrain_dag();
    let (c, t) = interior_triangle(&dag);
    dag.clusters[c].open_edges[t] = 0b001;
    assert_caught(&dag, "open-border marks");
}

#[test]
fn a_wrongly_cleared_mark_is_caught() {
    // Above level 0: a simplified group's output loses one of its open-border marks.
    let mut dag = terrain_dag();
    let (c, t) = dag
        .clusters
        .iter()
        .enumerate()
        .filter(|(_, k)| k.own_group != NO_GROUP)
        .find_map(|(c, k)| k.open_edges.iter().position(|&m| m != 0).map(|t| (c, t)))
        .expect("a marked edge above level 0");
    let mask = dag.clusters[c].open_edges[t];
    dag.clusters[c].open_edges[t] = mask & (mask - 1);
    assert_caught(&dag, "open-border marks");
}
