//! The importers' error paths, each with the message it must give: positions that are not
//! numbers, files with lines but no triangles, node hierarchies too deep to walk, files without a
//! scene, and `extras` that are not the object Portico reads tags from.

use base64::Engine;
use portico_data::import::import_bytes;
use serde_json::{Value, json};

/// A glTF with one triangle (positions as given), its node carrying `extras`, in `mode`
/// (4 = triangles, 1 = lines); the buffer is a data URI.
fn one_triangle(positions: [[f32; 3]; 3], mode: u32, extras: Value) -> Value {
    let mut bytes: Vec<u8> = positions
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    bytes.extend([0u16, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
    bytes.extend([0, 0]);
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bytes)
    );
    let finite = positions.iter().flatten().all(|x| x.is_finite());
    let (min, max) = if finite {
        let f = |k: usize, pick: fn(f32, f32) -> f32| {
            positions.iter().map(|p| p[k]).reduce(pick).unwrap_or(0.0)
        };
        (
            json!([f(0, f32::min), f(1, f32::min), f(2, f32::min)]),
            json!([f(0, f32::max), f(1, f32::max), f(2, f32::max)]),
        )
    } else {
        (json!([0, 0, 0]), json!([1, 1, 1]))
    };
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "wall", "extras": extras}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": mode}]}],
        "buffers": [{"byteLength": bytes.len(), "uri": uri}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": min, "max": max},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
        ]
    })
}

const TRIANGLE: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

fn import(doc: &Value) -> Result<portico_data::model::Model, String> {
    import_bytes(&serde_json::to_vec(doc).expect("json"), "gltf")
}

#[test]
fn the_reference_triangle_imports() {
    let m = import(&one_triangle(TRIANGLE, 4, Value::Null)).expect("import");
    assert_eq!(m.instances.len(), 1);
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
}

#[test]
fn positions_that_are_not_numbers_are_refused_naming_the_accessor() {
    let mut p = TRIANGLE;
    p[1][2] = f32::NAN;
    let e = import(&one_triangle(p, 4, Value::Null)).unwrap_err();
    assert_eq!(
        e,
        "node 0 'wall': mesh 0 primitive 0: accessor 0 (POSITION): element 1 is not a finite number"
    );
    let obj = "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n";
    let e = import_bytes(obj.as_bytes(), "obj").unwrap_err();
    assert!(
        e.contains("line 3") && e.contains("not a finite number"),
        "{e}"
    );
}

#[test]
fn a_file_with_lines_but_no_triangles_says_so() {
    let e = import(&one_triangle(TRIANGLE, 1, Value::Null)).unwrap_err();
    assert!(e.contains("contains no triangle meshes"), "{e}");
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\n";
    let e = import_bytes(obj.as_bytes(), "obj").unwrap_err();
    assert!(e.contains("contains no triangle meshes"), "{e}");
}

#[test]
fn a_hierarchy_deeper_than_256_is_refused_naming_the_node() {
    let mut doc = one_triangle(TRIANGLE, 4, Value::Null);
    // Node i's child is node i + 1; the mesh hangs at the bottom, 300 levels down.
    let nodes: Vec<Value> = (0..300)
        .map(|i| {
            if i == 299 {
                json!({"mesh": 0})
            } else {
                json!({"children": [i + 1]})
            }
        })
        .collect();
    doc["nodes"] = Value::Array(nodes);
    let e = import(&doc).unwrap_err();
    assert_eq!(e, "node 257: hierarchy deeper than 256");
    // 200 levels are walked: the triangle arrives.
    doc["nodes"] = Value::Array(
        (0..200)
            .map(|i| {
                if i == 199 {
                    json!({"mesh": 0})
                } else {
                    json!({"children": [i + 1]})
                }
            })
            .collect(),
    );
    assert_eq!(import(&doc).expect("200 levels").instances.len(), 1);
}

#[test]
fn a_file_without_a_scene_uses_every_root_node_with_a_warning() {
    let mut doc = one_triangle(TRIANGLE, 4, Value::Null);
    let o = doc.as_object_mut().expect("object");
    o.remove("scene");
    o.remove("scenes");
    let m = import(&doc).expect("import");
    assert_eq!(m.instances.len(), 1);
    assert_eq!(
        m.warnings,
        vec!["the file has no scene: every root node is used".to_string()]
    );
}

#[test]
fn extras_give_the_occluder_flag_and_scalar_tags_and_anything_else_is_ignored() {
    let m = import(&one_triangle(
        TRIANGLE,
        4,
        json!({"occluder": true, "room": "101", "storey": 2, "list": [1, 2], "nested": {"a": 1}}),
    ))
    .expect("import");
    let i = &m.instances[0];
    assert!(i.occluder);
    let tags: Vec<(&str, &str)> = i
        .tags
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    assert_eq!(tags, [("room", "101"), ("storey", "2")]);
    for extras in [
        json!("a string"),
        json!([1, 2, 3]),
        json!(42),
        json!({"occluder": "yes"}),
    ] {
        let m = import(&one_triangle(TRIANGLE, 4, extras.clone())).expect("import");
        let i = &m.instances[0];
        assert!(!i.occluder, "{extras}: not a boolean, not an occluder");
    }
}

#[test]
fn a_glb_whose_header_declares_fewer_bytes_than_itself_is_refused_not_a_panic() {
    // The `gltf` crate would subtract the header from the declared length unchecked.
    for declared in [0u32, 11] {
        let mut glb = b"glTF".to_vec();
        glb.extend(2u32.to_le_bytes());
        glb.extend(declared.to_le_bytes());
        glb.extend([0; 64]);
        let err = import_bytes(&glb, "glb").expect_err("a broken GLB");
        assert!(err.contains(&format!("declares {declared} bytes")), "{err}");
    }
    let err = import_bytes(b"glTF\x02\x00\x00\x00\x10", "glb").expect_err("truncated");
    assert!(err.contains("truncated"), "{err}");
}
