//! The .mres container: byte-exact round trips, and corrupt input always gives an error
//! (truncation at every length, every byte flipped), never a panic.

use mres_format::bits::{oct_decode, oct_encode};
use mres_format::{
    write_mres, Dag, DagCluster, Grid, Group, Header, MresError, MresFile, Sphere, UvQuant, FLAG_MATERIALS,
    FLAG_NORMALS, FLAG_UVS, NO_GROUP,
};

/// A small two-level DAG: a strip of 4 level-0 clusters in one group, simplified into one root
/// cluster. Normals and UVs are chosen exactly representable so decoding is exact.
fn sample_dag() -> Dag {
    let normal_bits = 10;
    let n = oct_decode(oct_encode([0.0, 0.0, 1.0], normal_bits), normal_bits);
    let uv = UvQuant { min: [0.0, 0.0], extent: [1.0, 1.0] };
    let cluster = |x0: i32, group: u32, own_group: u32, material: u16| {
        let positions = vec![[x0, 0, 5], [x0 + 100, 0, 5], [x0, 100, 5], [x0 + 100, 100, 7]];
        DagCluster {
            group,
            own_group,
            uvs: positions
                .iter()
                .map(|p| uv.decode(uv.quantize([p[0] as f32 / 1000.0, p[1] as f32 / 1000.0])))
                .collect(),
            normals: vec![n; 4],
            positions,
            indices: vec![0, 1, 2, 1, 3, 2],
            materials: vec![material, material + 1],
        }
    };
    let mut clusters: Vec<DagCluster> = (0..4).map(|i| cluster(i * 100, 0, NO_GROUP, i as u16)).collect();
    clusters.push(cluster(0, 1, 0, 9));
    let sphere = |r| Sphere { center: [0.2, 0.05, 0.005], radius: r };
    Dag {
        header: Header {
            flags: FLAG_NORMALS | FLAG_UVS | FLAG_MATERIALS,
            grid: Grid { origin: [0.0; 3], step: 0.001 },
            uv,
            normal_bits,
            position_bits: 16,
            level_count: 0,
            source_triangles: 8,
        },
        groups: vec![
            Group { sphere: sphere(1.0), error: 0.01, level: 0, first_cluster: 0, cluster_count: 0, page: 0 },
            Group { sphere: sphere(2.0), error: f32::INFINITY, level: 1, first_cluster: 0, cluster_count: 0, page: 0 },
        ],
        clusters,
    }
}

#[test]
fn round_trip_is_exact() {
    let dag = sample_dag();
    let bytes = write_mres(&dag, 3).unwrap();
    let file = MresFile::parse(bytes.clone()).unwrap();
    // Coarse to fine: the root group comes first.
    assert_eq!(file.groups[0].error, f32::INFINITY);
    assert_eq!(file.header.level_count, 2);
    let decoded = file.decode_all().unwrap();
    // Map back: file cluster 0 is the root cluster, then the four level-0 clusters.
    let order = [4usize, 0, 1, 2, 3];
    for (i, d) in decoded.iter().enumerate() {
        let c = &dag.clusters[order[i]];
        assert_eq!(d.positions, c.positions);
        assert_eq!(d.indices, c.indices);
        assert_eq!(d.materials, c.materials);
        assert_eq!(d.uvs, c.uvs);
        assert_eq!(d.normals, c.normals);
    }
    // Writing what was read gives the same bytes.
    let again = Dag {
        header: file.header,
        groups: file.groups.clone(),
        clusters: decoded
            .into_iter()
            .zip(&file.clusters)
            .map(|(d, info)| DagCluster {
                group: info.group,
                own_group: info.own_group,
                positions: d.positions,
                normals: d.normals,
                uvs: d.uvs,
                indices: d.indices,
                materials: d.materials,
            })
            .collect(),
    };
    assert_eq!(write_mres(&again, 3).unwrap(), bytes);
}

fn parse_and_decode(bytes: Vec<u8>) -> Result<(), MresError> {
    let file = MresFile::parse(bytes)?;
    file.decode_all().map(|_| ())
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    for len in 0..bytes.len() {
        let result = parse_and_decode(bytes[..len].to_vec());
        assert!(result.is_err(), "truncated to {len} of {} bytes was accepted", bytes.len());
    }
    assert!(parse_and_decode(bytes).is_ok());
}

#[test]
fn every_flipped_byte_is_an_error() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    for at in 0..bytes.len() {
        for mask in [0x01u8, 0x80, 0xff] {
            let mut corrupt = bytes.clone();
            corrupt[at] ^= mask;
            assert!(parse_and_decode(corrupt).is_err(), "flipping byte {at} with {mask:#x} was accepted");
        }
    }
}

#[test]
fn typed_errors() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    let mut v = bytes.clone();
    v[4] = 2;
    assert_eq!(MresFile::parse(v).unwrap_err(), MresError::WrongVersion { found: 2 });
    let mut v = bytes.clone();
    v[0] = b'X';
    assert_eq!(MresFile::parse(v).unwrap_err(), MresError::BadMagic);
    assert!(matches!(MresFile::parse(bytes[..100].to_vec()), Err(MresError::Truncated { .. })));
    let mut v = bytes.clone();
    let last = v.len() - 1;
    v[last] ^= 1;
    let file = MresFile::parse(v).unwrap();
    let last_page = file.pages.len() as u32 - 1;
    assert_eq!(file.page(last_page).unwrap_err(), MresError::Checksum(format!("page {last_page}")));
}

/// A page whose table entry claims a huge decompressed size is rejected before any allocation.
#[test]
fn huge_claimed_page_size_is_rejected() {
    let bytes = write_mres(&sample_dag(), 3).unwrap();
    let file = MresFile::parse(bytes.clone()).unwrap();
    let table = 160 + file.groups.len() * 40 + file.clusters.len() * 16;
    let mut v = bytes;
    v[table + 12..table + 16].copy_from_slice(&u32::MAX.to_le_bytes());
    // Fix the meta checksum so that only the size check can catch it.
    let hierarchy_end = table;
    let table_size = u64::from_le_bytes(v[104..112].try_into().unwrap()) as usize;
    let mut h = blake3::Hasher::new();
    h.update(&v[..112]);
    h.update(&v[160..hierarchy_end]);
    h.update(&v[table..table + table_size]);
    let sum = *h.finalize().as_bytes();
    v[112..144].copy_from_slice(&sum);
    let err = MresFile::parse(v).unwrap_err();
    assert!(matches!(err, MresError::Corrupt(ref m) if m.contains("decompressed")), "{err}");
}
