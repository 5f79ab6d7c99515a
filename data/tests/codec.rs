//! Compressed geometry segments (`portico build --compress`): every LOD of a generated building
//! decodes to the same mesh within half a quantisation step, in well under half the bytes, and
//! damaged or hostile segments are refused with a message, never a panic.

use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::codec::{self, decode, encode, is_compressed, to_gpu_layout};
use portico_data::geometry::{
    GEOMETRY_DEFLATE, GeometryHeader, GeometryView, Mesh, Vertex, encode_geometry,
};
use portico_data::import::import_file;
use portico_data::stats::stats;
use std::path::PathBuf;

mod common;

/// The tiny generated building, built plain and compressed (flattened: every instance's own
/// world-space geometry, the case where bytes matter most).
fn both() -> (tempfile::TempDir, PathBuf, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let glb = common::tiny_glb(dir.path(), 5, 1);
    let out = |name: &str, compress: bool| {
        let path = dir.path().join(name);
        let opts = BuildOptions {
            flatten: true,
            no_hierarchy: true,
            no_cells: true,
            compress,
            ..BuildOptions::default()
        };
        build(import_file(&glb).unwrap(), &path, &opts, &Quiet).unwrap();
        path
    };
    let plain = out("plain.portico", false);
    let packed = out("packed.portico", true);
    (dir, plain, packed)
}

#[test]
fn every_lod_decodes_to_the_same_mesh_in_fewer_bytes() {
    let (_dir, plain, packed) = both();
    let (a, b) = (
        Database::open(&plain).unwrap(),
        Database::open(&packed).unwrap(),
    );
    b.verify_all().expect("a compressed database verifies");
    let (ha, hb) = (a.header(), b.header());
    assert_eq!(ha.instances.len(), hb.instances.len());
    let mut compared = 0;
    for (ia, ib) in ha.instances.iter().zip(&hb.instances) {
        for (la, lb) in ha.lods_of(ia).iter().zip(hb.lods_of(ib)) {
            assert!(is_compressed(&b.segment(lb.segment).unwrap()));
            assert!(!is_compressed(&a.segment(la.segment).unwrap()));
            let ma = GeometryView::parse(&a.geometry(la).unwrap())
                .unwrap()
                .to_mesh();
            let mb = GeometryView::parse(&b.geometry(lb).unwrap())
                .unwrap()
                .to_mesh();
            assert_eq!(
                rotated(&ma.indices),
                rotated(&mb.indices),
                "same triangles, same order and winding"
            );
            assert_eq!(ma.vertices.len(), mb.vertices.len());
            let tol = codec::position_tolerance(&ma);
            for (va, vb) in ma.vertices.iter().zip(&mb.vertices) {
                assert_eq!(
                    (va.normal, va.color),
                    (vb.normal, vb.color),
                    "exact attributes"
                );
                for (k, t) in tol.iter().enumerate() {
                    let d = (va.position[k] - vb.position[k]).abs();
                    assert!(d <= t * 1.01 + 1e-6, "axis {k}: moved {d} > {t}");
                }
            }
            compared += 1;
        }
    }
    assert!(compared > 100, "{compared} LODs compared");
    // The wire cost: bytes per stored triangle over all LODs (the plain layout is ~45).
    let (sa, sb) = (stats(&a), stats(&b));
    assert_eq!(sa.triangles_stored, sb.triangles_stored);
    // The segment index says which segments are compressed and what they decode to: exactly
    // the plain file's bytes.
    let flagged = b
        .segments()
        .iter()
        .filter(|e| e.flags & portico_data::format::segment_flags::MESHOPT != 0)
        .count() as u64;
    assert!(flagged > 100 && flagged == sb.compressed_segments);
    assert_eq!(sa.compressed_segments, 0);
    assert_eq!(sa.geometry_decoded_bytes, sa.geometry_bytes);
    assert_eq!(sb.geometry_decoded_bytes, sa.geometry_bytes);
    assert!(sb.to_text().contains("meshopt-compressed"));
    let per =
        |s: &portico_data::stats::DbStats| s.geometry_bytes as f64 / s.triangles_stored as f64;
    println!(
        "bytes per stored triangle: plain {:.1}, compressed {:.1}",
        per(&sa),
        per(&sb)
    );
    // Issue #17's target on the wire: at most 8 bytes per triangle over all LODs (measured:
    // 7.7 here, 44.7 plain; meshopt alone gave 13.0 on flattened soda, 7.9 with deflate).
    assert!(
        per(&sb) <= 8.0,
        "{:.1} bytes per stored triangle (plain {:.1})",
        per(&sb),
        per(&sa)
    );
}

/// Each triangle rotated to start at its smallest index: the index codec keeps triangles, their
/// order and their winding, but may start a triangle at another of its corners.
fn rotated(indices: &[u32]) -> Vec<[u32; 3]> {
    indices
        .chunks_exact(3)
        .map(|t| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        })
        .collect()
}

fn quad() -> Mesh {
    let v = |x: f32, y: f32| Vertex::new([x, y, 0.25], [0.0, 0.0, 1.0], [0.5, 0.25, 1.0, 1.0]);
    Mesh {
        vertices: vec![v(0.0, 0.0), v(3.0, 0.0), v(3.0, 2.0), v(0.0, 2.0)],
        indices: vec![0, 1, 2, 0, 2, 3],
        uvs: Vec::new(),
    }
}

#[test]
fn plain_segments_pass_through_and_compressed_ones_are_not_parsed_raw() {
    let plain = encode_geometry(&quad());
    assert!(matches!(
        to_gpu_layout(&plain).unwrap(),
        std::borrow::Cow::Borrowed(_)
    ));
    let packed = encode(&quad());
    let err = GeometryView::parse(&packed).unwrap_err();
    assert!(err.contains("compressed"), "{err}");
    let decoded = to_gpu_layout(&packed).unwrap();
    let back = GeometryView::parse(&decoded).unwrap().to_mesh();
    assert_eq!(rotated(&back.indices), rotated(&quad().indices));
    for (a, b) in back.vertices.iter().zip(&quad().vertices) {
        assert_eq!((a.normal, a.color), (b.normal, b.color));
        assert!(glam::Vec3::from(a.position).distance(b.position.into()) < 1e-5);
    }
    // An empty mesh and a single point survive too (zero extent: no division by zero).
    let empty = decode(&encode(&Mesh::default())).unwrap();
    assert_eq!(
        GeometryView::parse(&empty).unwrap().to_mesh(),
        Mesh::default()
    );
    let point = Mesh {
        vertices: vec![quad().vertices[0]; 3],
        indices: vec![0, 1, 2],
        uvs: Vec::new(),
    };
    let back = GeometryView::parse(&decode(&encode(&point)).unwrap())
        .unwrap()
        .to_mesh();
    assert_eq!(
        (back.vertices, rotated(&back.indices)),
        (point.vertices, rotated(&point.indices))
    );
}

#[test]
fn a_compressed_segment_decodes_only_to_what_its_lod_record_says() {
    // What the client's IO stage (native) and the page (wasm) call for each geometry segment.
    let packed = encode(&quad());
    let plain = encode_geometry(&quad());
    let size = plain.len() as u64;
    let decoded = codec::to_gpu_layout_as(7, &packed, Some(size)).unwrap();
    assert_eq!(decoded.len() as u64, size);
    // A record that promises another size, or none, refuses the segment before decoding.
    for expected in [Some(size + 4), Some(size - 4), None] {
        let err = codec::to_gpu_layout_as(7, &packed, expected).unwrap_err();
        assert!(
            err.starts_with("segment 7: its counts (4 vertices, 6 indices) disagree"),
            "{err}"
        );
    }
    // A plain segment needs no record; a broken one is named.
    assert!(codec::to_gpu_layout_as(7, &plain, None).is_ok());
    let err = codec::to_gpu_layout_as(9, &plain[..20], None).unwrap_err();
    assert!(err.starts_with("segment 9: "), "{err}");
}

/// A grid of `n` vertices in strips (many codec blocks; wide indices past 65,536 vertices).
fn strip(n: u32) -> Mesh {
    let w = 256u32;
    let vertices = (0..n)
        .map(|i| {
            let (x, z) = ((i % w) as f32 * 0.05, (i / w) as f32 * 0.05);
            Vertex::new(
                [x, (x * 3.0).sin() * 0.1, z],
                [0.0, 1.0, 0.0],
                [0.2, 0.4, (i % 7) as f32 / 7.0, 1.0],
            )
        })
        .collect();
    let indices = (0..n.saturating_sub(w + 1))
        .filter(|i| i % w != w - 1)
        .flat_map(|i| [i, i + w, i + 1, i + 1, i + w, i + w + 1])
        .collect();
    Mesh {
        vertices,
        indices,
        uvs: Vec::new(),
    }
}

#[test]
fn texture_coordinates_round_trip_bit_for_bit_and_the_record_counts_them() {
    let mut mesh = strip(3_000);
    mesh.uvs = (0..3_000)
        .map(|i| [(i % 256) as f32 * 0.37 - 20.0, (i / 256) as f32 * 1.5])
        .collect();
    let packed = encode(&mesh);
    let plain = encode_geometry(&mesh);
    assert!(
        packed.len() * 2 < plain.len(),
        "{} of {}",
        packed.len(),
        plain.len()
    );
    // The LOD record's size (with coordinates) is what it decodes to; without, it is refused.
    let (v, t) = (mesh.vertices.len() as u32, mesh.triangle_count() as u32);
    let with = portico_data::geometry::plain_size(v, t, true);
    assert_eq!(with, plain.len() as u64);
    let decoded = codec::to_gpu_layout_as(3, &packed, Some(with)).unwrap();
    let back = GeometryView::parse(&decoded).unwrap().to_mesh();
    assert_eq!(back.uvs, mesh.uvs);
    assert_eq!(rotated(&back.indices), rotated(&mesh.indices));
    let without = portico_data::geometry::plain_size(v, t, false);
    assert!(codec::to_gpu_layout_as(3, &packed, Some(without)).is_err());
}

#[test]
fn large_meshes_and_repeated_vertices_round_trip() {
    // 70,000 vertices: 274 codec blocks and u32 indices in the plain layout.
    for mesh in [strip(1_000), strip(70_000)] {
        let back = GeometryView::parse(&decode(&encode(&mesh)).unwrap())
            .unwrap()
            .to_mesh();
        assert_eq!(rotated(&back.indices), rotated(&mesh.indices));
        let tol = codec::position_tolerance(&mesh);
        let b = mesh.bounds();
        for (a, v) in back.vertices.iter().zip(&mesh.vertices) {
            assert_eq!((a.normal, a.color), (v.normal, v.color));
            for (k, t) in tol.iter().enumerate() {
                let p = a.position[k];
                assert!((p - v.position[k]).abs() <= t * 1.001 + 1e-6);
                // The grid ends on the largest coordinate: nothing leaves the bounds (but for
                // the last bit of a float).
                assert!(
                    p >= b.min[k] - 1e-5 && p <= b.max[k] + 1e-5,
                    "axis {k}: {p} outside"
                );
            }
        }
    }
    // 20,000 identical vertices cost almost nothing to encode and must still decode.
    let same = Mesh {
        vertices: vec![quad().vertices[1]; 20_000],
        indices: vec![0, 1, 2],
        uvs: Vec::new(),
    };
    let packed = encode(&same);
    assert!(packed.len() < 1_000, "{} bytes", packed.len());
    let back = GeometryView::parse(&decode(&packed).unwrap())
        .unwrap()
        .to_mesh();
    assert_eq!(back.vertices.len(), 20_000);
}

#[test]
fn damaged_or_hostile_segments_are_refused_not_panicked_on() {
    // Both layouts: meshopt alone (files built before the deflate stage), and deflated.
    let deflated = encode(&strip(600));
    let h: GeometryHeader = bytemuck::pod_read_unaligned(&deflated[..32]);
    assert!(
        h.flags & GEOMETRY_DEFLATE != 0,
        "a 600-vertex strip deflates"
    );
    for packed in [codec::encode_meshopt(&quad()), deflated] {
        refused_when_damaged(&packed);
    }
}

fn refused_when_damaged(packed: &[u8]) {
    // Every truncation is refused.
    for n in 0..packed.len() - 3 {
        assert!(decode(&packed[..n]).is_err(), "truncated to {n} bytes");
    }
    // Every single-byte flip either decodes to a mesh that parses or is refused.
    for i in 0..packed.len() {
        let mut b = packed.to_vec();
        b[i] ^= 0x5a;
        if let Ok(d) = to_gpu_layout(&b) {
            GeometryView::parse(&d).expect("whatever decodes parses");
        }
    }
    // A header claiming far more than its streams could hold allocates nothing.
    let mut h: GeometryHeader = bytemuck::pod_read_unaligned(&packed[..32]);
    h.vertex_count = 50_000_000;
    let mut b = packed.to_vec();
    b[..32].copy_from_slice(bytemuck::bytes_of(&h));
    let err = decode(&b).unwrap_err();
    assert!(err.contains("more than"), "{err}");
    let mut h: GeometryHeader = bytemuck::pod_read_unaligned(&packed[..32]);
    h.index_count = 3_000;
    b[..32].copy_from_slice(bytemuck::bytes_of(&h));
    assert!(decode(&b).unwrap_err().contains("more than"));
}

#[test]
fn the_deflate_stage_is_lossless_and_inflates_no_further_than_its_header_says() {
    let mesh = strip(2_000);
    let (meshopt, deflated) = (codec::encode_meshopt(&mesh), encode(&mesh));
    assert!(
        deflated.len() < meshopt.len(),
        "{} vs {}",
        deflated.len(),
        meshopt.len()
    );
    assert_eq!(decode(&deflated).unwrap(), decode(&meshopt).unwrap());
    // A bomb: a header whose streams end after 100 bytes over a deflate stream of a megabyte
    // of zeros inflates 76 bytes and is refused.
    let mut h: GeometryHeader = bytemuck::pod_read_unaligned(&deflated[..32]);
    h.vertex_offset = 56;
    h.reserved = [20, 20];
    h.index_offset = 76;
    let mut bomb = bytemuck::bytes_of(&h).to_vec();
    bomb.extend(miniz_oxide::deflate::compress_to_vec(
        &vec![0u8; 1 << 20],
        6,
    ));
    let err = decode(&bomb).unwrap_err();
    assert!(err.contains("inflate"), "{err}");
    // Streams that end before the quantisation block are refused before inflating.
    h.vertex_offset = 32;
    h.index_offset = 32;
    h.reserved = [0, 0];
    let mut short = bytemuck::bytes_of(&h).to_vec();
    short.extend_from_slice(&deflated[32..]);
    assert!(decode(&short).unwrap_err().contains("declares"));
}
