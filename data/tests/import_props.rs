//! Property tests of the importers on hostile input: whatever is done to a valid file (bytes
//! flipped, JSON fields set to any value, buffers scribbled on), importing it gives a model or
//! an error, never a panic. `fuzz/fuzz_targets/import.rs` runs the same entry point under
//! libFuzzer for longer.

use base64::Engine;
use portico_data::import::import_bytes;
use proptest::prelude::*;

fn case(name: &str) -> Vec<u8> {
    std::fs::read(format!(
        "{}/tests/cases/import/{name}",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

/// Imports and asserts that it did not panic; an error must be one line.
fn no_panic(bytes: &[u8], ext: &str) {
    match std::panic::catch_unwind(|| import_bytes(bytes, ext)) {
        Err(_) => panic!("the {ext} importer panicked"),
        Ok(Err(e)) => assert!(!e.contains('\n'), "not one line: {e}"),
        Ok(Ok(m)) => {
            for d in &m.defs {
                for l in &d.lods {
                    l.validate().unwrap();
                }
            }
        }
    }
}

/// JSON paths into a glTF that decide how bytes are read.
const FIELDS: &[&[&str]] = &[
    &["accessors", "#", "count"],
    &["accessors", "#", "byteOffset"],
    &["accessors", "#", "componentType"],
    &["accessors", "#", "bufferView"],
    &["accessors", "#", "normalized"],
    &["bufferViews", "#", "byteLength"],
    &["bufferViews", "#", "byteOffset"],
    &["bufferViews", "#", "byteStride"],
    &["bufferViews", "#", "buffer"],
    &["buffers", "#", "byteLength"],
    &["meshes", "#", "primitives", "0", "mode"],
    &["meshes", "#", "primitives", "0", "indices"],
    &["meshes", "#", "primitives", "0", "attributes", "POSITION"],
    &["nodes", "#", "mesh"],
    &["nodes", "#", "translation"],
    &["nodes", "#", "scale"],
    &["nodes", "#", "children"],
    &["scenes", "0", "nodes"],
];

fn value_strategy() -> impl Strategy<Value = serde_json::Value> {
    prop_oneof![
        any::<i64>().prop_map(serde_json::Value::from),
        (0u64..64).prop_map(serde_json::Value::from),
        prop::sample::select(vec![5120u64, 5121, 5122, 5123, 5125, 5126, 5130])
            .prop_map(serde_json::Value::from),
        any::<f64>().prop_map(|f| serde_json::Number::from_f64(f)
            .map_or(serde_json::Value::Null, serde_json::Value::Number)),
        Just(serde_json::json!([1e30, -1e30, 0.5])),
        Just(serde_json::json!([0, 0, 0])),
        Just(serde_json::json!([0])),
        Just(serde_json::Value::Null),
        Just(serde_json::json!("x")),
        Just(serde_json::json!(true)),
    ]
}

/// Sets `path` (with `#` replaced by `index`, modulo the array's length) in `doc` to `value`,
/// where its parent exists.
fn set(doc: &mut serde_json::Value, path: &[&str], index: usize, value: serde_json::Value) {
    let mut pointer = String::new();
    for key in &path[..path.len() - 1] {
        let step = match (*key, doc.pointer(&pointer)) {
            ("#", Some(serde_json::Value::Array(a))) if !a.is_empty() => {
                (index % a.len()).to_string()
            }
            ("#", _) => return,
            (k, _) => k.to_string(),
        };
        pointer.push('/');
        pointer.push_str(&step);
    }
    match doc.pointer_mut(&pointer) {
        Some(serde_json::Value::Object(o)) => {
            o.insert(path[path.len() - 1].to_string(), value);
        }
        Some(serde_json::Value::Array(a)) => {
            if let Some(slot) = path[path.len() - 1]
                .parse::<usize>()
                .ok()
                .and_then(|n| a.get_mut(n))
            {
                *slot = value;
            }
        }
        _ => {}
    }
}

/// Found by `fuzz/fuzz_targets/import.rs`: the `gltf` crate's own validation indexed a POSITION
/// accessor that does not exist.
#[test]
fn a_position_accessor_that_does_not_exist_is_an_error() {
    let mut doc: serde_json::Value = serde_json::from_slice(&case("quantized.gltf")).unwrap();
    doc["meshes"][3]["primitives"][0]["attributes"]["POSITION"] = 99.into();
    let e = import_bytes(&serde_json::to_vec(&doc).unwrap(), "gltf").unwrap_err();
    assert_eq!(e, "mesh 3 primitive 0: POSITION accessor 99 does not exist");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn gltf_with_any_field_set_to_anything_never_panics(
        file in prop::sample::select(vec!["quantized.gltf", "skinned-curtain.gltf", "stray-object-3km.gltf"]),
        edits in prop::collection::vec((0..FIELDS.len(), 0usize..64, value_strategy()), 1..4),
    ) {
        let mut doc: serde_json::Value = serde_json::from_slice(&case(file)).unwrap();
        for (f, i, v) in edits {
            set(&mut doc, FIELDS[f], i, v);
        }
        no_panic(&serde_json::to_vec(&doc).unwrap(), "gltf");
    }

    #[test]
    fn gltf_with_scribbled_buffers_never_panics(
        file in prop::sample::select(vec!["quantized.gltf", "skinned-curtain.gltf", "house-far-origin.obj"]),
        flips in prop::collection::vec((any::<usize>(), any::<u8>()), 1..16),
    ) {
        if file.ends_with(".obj") {
            let mut bytes = case(file);
            for (at, b) in flips {
                let n = at % bytes.len();
                bytes[n] = b;
            }
            no_panic(&bytes, "obj");
        } else {
            let b64 = base64::engine::general_purpose::STANDARD;
            let mut doc: serde_json::Value = serde_json::from_slice(&case(file)).unwrap();
            let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
            let mut raw = b64.decode(uri.split_once(";base64,").unwrap().1).unwrap();
            for (at, b) in flips {
                let n = at % raw.len();
                raw[n] = b;
            }
            doc["buffers"][0]["uri"] = format!("data:application/octet-stream;base64,{}", b64.encode(&raw)).into();
            no_panic(&serde_json::to_vec(&doc).unwrap(), "gltf");
        }
    }

    #[test]
    fn any_bytes_as_glb_or_obj_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let mut glb = b"glTF\x02\x00\x00\x00".to_vec();
        glb.extend(&bytes);
        no_panic(&glb, "glb");
        no_panic(&bytes, "obj");
    }
}
