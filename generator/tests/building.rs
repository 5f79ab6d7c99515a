//! End-to-end checks of generated buildings: determinism, scale, reachability, and that the GLB
//! honours the contract the builder relies on (occluder tags, true openings, shared furniture
//! with halving `MSFT_lod` chains).

use std::collections::{BTreeMap, BTreeSet, VecDeque};

use portico_generator::{Building, GenerateError, MAX_FLOORS, Params, Preset, RoomKind, generate};
use serde_json::Value;

fn build(preset: Preset, seed: u64, floors: Option<u32>) -> Building {
    let params = Params {
        preset,
        seed,
        floors,
    };
    match generate(&params, &mut |_| {}) {
        Ok(b) => b,
        Err(e) => panic!("generate {preset} failed: {e}"),
    }
}

#[test]
fn preset_names_round_trip() {
    for p in Preset::ALL {
        assert_eq!(p.to_string().parse::<Preset>(), Ok(p));
    }
    assert_eq!("SODA".parse::<Preset>(), Ok(Preset::Soda));
    assert!("huge".parse::<Preset>().is_err());
    assert_eq!(RoomKind::Auditorium.to_string(), "auditorium");
}

#[test]
fn same_seed_gives_same_bytes_and_other_seeds_differ() {
    for preset in [Preset::Tiny, Preset::Small] {
        let a = build(preset, 42, None);
        let b = build(preset, 42, None);
        let c = build(preset, 43, None);
        assert!(a.glb == b.glb, "{preset}: same seed, different bytes");
        assert_eq!(a.stats, b.stats);
        assert!(a.glb != c.glb, "{preset}: different seeds, same bytes");
    }
}

#[test]
fn invalid_storey_counts_are_rejected() {
    for floors in [0, MAX_FLOORS + 1] {
        let params = Params {
            preset: Preset::Tiny,
            seed: 1,
            floors: Some(floors),
        };
        let result = generate(&params, &mut |_| {});
        assert!(matches!(result, Err(GenerateError::InvalidFloors(f)) if f == floors));
    }
}

#[test]
fn progress_counts_up_to_total() {
    let mut seen = Vec::new();
    let params = Params {
        preset: Preset::Tiny,
        seed: 3,
        floors: Some(3),
    };
    let building = generate(&params, &mut |p| seen.push((p.done, p.total)));
    assert!(building.is_ok());
    assert_eq!(seen.last(), Some(&(4, 4)));
    assert!(seen.windows(2).all(|w| w[0].0 < w[1].0));
}

#[test]
fn tiny_is_small() {
    let b = build(Preset::Tiny, 1, None);
    let s = &b.stats;
    assert_eq!(s.storeys, 1);
    assert!((3..=8).contains(&s.rooms), "{s:?}");
    assert!((50..=300).contains(&s.instances), "{s:?}");
    assert!(s.triangles_highest <= 30_000, "{s:?}");
    assert_eq!(b.rooms.len() as u32, s.rooms);
}

#[test]
fn small_is_within_bounds() {
    let s = build(Preset::Small, 1, None).stats;
    assert!((1..=2).contains(&s.storeys), "{s:?}");
    assert!((1_000..=3_000).contains(&s.instances), "{s:?}");
    assert!((100_000..=400_000).contains(&s.triangles_highest), "{s:?}");
}

#[test]
fn soda_matches_soda_hall_scale() {
    let b = build(Preset::Soda, 1, None);
    let s = &b.stats;
    assert!(s.storeys >= 7, "{s:?}");
    assert!(s.instances >= 14_000, "{s:?}");
    assert!(s.triangles_highest >= 1_400_000, "{s:?}");
    assert!(s.triangles_all_lods > s.triangles_highest);
    assert!((60..=140).contains(&s.furniture_definitions), "{s:?}");
    for kind in [RoomKind::Auditorium, RoomKind::Library] {
        let storeys: BTreeSet<u32> = b
            .rooms
            .iter()
            .filter(|r| r.kind == kind)
            .map(|r| r.storey)
            .collect();
        assert!(storeys.len() >= 2, "{kind} on storeys {storeys:?}");
    }
    assert_reachable(&b);
}

/// Mega is ~160k instances and a ~45 MB GLB; it still generates in about 3 s in a debug build.
#[test]
fn mega_is_ten_times_soda() {
    let soda = build(Preset::Soda, 1, None).stats;
    let mega = build(Preset::Mega, 1, None);
    let s = &mega.stats;
    assert!(s.instances >= 10 * soda.instances, "{s:?}");
    assert!(s.triangles_highest >= 10 * soda.triangles_highest, "{s:?}");
    assert_reachable(&mega);
}

#[test]
fn floors_override_stacks_connected_storeys() {
    let b = build(Preset::Tiny, 5, Some(4));
    assert_eq!(b.stats.storeys, 4);
    let storeys: BTreeSet<u32> = b.rooms.iter().map(|r| r.storey).collect();
    assert_eq!(storeys.len(), 4);
    let storey_of: BTreeMap<u32, u32> = b.rooms.iter().map(|r| (r.id, r.storey)).collect();
    let stair_links = b
        .doors
        .iter()
        .filter(|d| storey_of.get(&d.rooms.0) != storey_of.get(&d.rooms.1))
        .count();
    assert!(stair_links >= 3, "only {stair_links} stair openings");
    assert_reachable(&b);
    check_glb(&b);
    check_openings_are_gaps(&b);
}

#[test]
fn small_building_has_every_room_kind_and_is_connected() {
    let b = build(Preset::Small, 7, None);
    let kinds: BTreeSet<RoomKind> = b.rooms.iter().map(|r| r.kind).collect();
    for kind in [
        RoomKind::Office,
        RoomKind::Lab,
        RoomKind::Classroom,
        RoomKind::Conference,
        RoomKind::Auditorium,
        RoomKind::Library,
        RoomKind::Corridor,
        RoomKind::Stairwell,
    ] {
        assert!(kinds.contains(&kind), "no {kind}");
    }
    assert_reachable(&b);
}

#[test]
fn tiny_and_small_glb_honour_the_contract() {
    check_glb(&build(Preset::Tiny, 1, None));
    check_glb(&build(Preset::Small, 2, None));
}

#[test]
fn door_and_stair_openings_are_true_gaps_in_occluders() {
    check_openings_are_gaps(&build(Preset::Small, 3, None));
}

/// Every room reaches every other through `doors` (BFS).
fn assert_reachable(b: &Building) {
    let ids: BTreeSet<u32> = b.rooms.iter().map(|r| r.id).collect();
    let mut adjacency: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for d in &b.doors {
        assert!(
            ids.contains(&d.rooms.0) && ids.contains(&d.rooms.1),
            "{d:?}"
        );
        assert_ne!(d.rooms.0, d.rooms.1);
        for k in 0..3 {
            assert!(d.min[k] < d.max[k], "{d:?} is empty");
        }
        adjacency.entry(d.rooms.0).or_default().push(d.rooms.1);
        adjacency.entry(d.rooms.1).or_default().push(d.rooms.0);
    }
    let Some(&start) = ids.first() else {
        panic!("no rooms");
    };
    let mut seen = BTreeSet::from([start]);
    let mut queue = VecDeque::from([start]);
    while let Some(r) = queue.pop_front() {
        for &n in adjacency.get(&r).map_or(&[][..], Vec::as_slice) {
            if seen.insert(n) {
                queue.push_back(n);
            }
        }
    }
    let unreachable: Vec<_> = ids.difference(&seen).collect();
    assert!(unreachable.is_empty(), "unreachable rooms {unreachable:?}");
}

fn extras_of(node: &gltf::Node) -> Value {
    node.extras()
        .as_ref()
        .and_then(|raw| serde_json::from_str(raw.get()).ok())
        .unwrap_or(Value::Null)
}

/// Nodes reachable from the scene roots, with their accumulated translation.
fn scene_nodes(doc: &gltf::Document) -> Vec<(gltf::Node<'_>, [f32; 3])> {
    let mut out = Vec::new();
    let mut stack: Vec<(gltf::Node, [f32; 3])> = doc
        .default_scene()
        .map(|s| s.nodes().map(|n| (n, [0.0; 3])).collect())
        .unwrap_or_default();
    while let Some((node, parent)) = stack.pop() {
        let (t, _, _) = node.transform().decomposed();
        let world = [parent[0] + t[0], parent[1] + t[1], parent[2] + t[2]];
        for child in node.children() {
            stack.push((child, world));
        }
        out.push((node, world));
    }
    out
}

fn triangle_count(mesh: &gltf::Mesh) -> u64 {
    mesh.primitives()
        .map(|p| p.indices().map_or(0, |a| a.count() as u64 / 3))
        .sum()
}

fn check_glb(b: &Building) {
    let gltf = match gltf::Gltf::from_slice(&b.glb) {
        Ok(g) => g,
        Err(e) => panic!("not a valid GLB: {e}"),
    };
    assert_eq!(gltf.document.as_json().asset.version, "2.0");
    assert_eq!(
        gltf.document.as_json().asset.generator.as_deref(),
        Some("portico-generator")
    );
    assert!(gltf.document.extensions_used().any(|e| e == "MSFT_lod"));
    assert!(!gltf.document.extensions_required().any(|e| e == "MSFT_lod"));
    let (doc, buffers, _) = match gltf::import_slice(&b.glb) {
        Ok(x) => x,
        Err(e) => panic!("buffers do not resolve: {e}"),
    };
    for mesh in doc.meshes() {
        for prim in mesh.primitives() {
            assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
            let pos = prim.get(&gltf::Semantic::Positions);
            assert!(
                pos.as_ref()
                    .is_some_and(|a| a.min().is_some() && a.max().is_some())
            );
            let reader = prim.reader(|buf| buffers.get(buf.index()).map(|d| &d.0[..]));
            let count = reader.read_positions().map_or(0, Iterator::count);
            assert!(count > 0);
            assert_eq!(reader.read_normals().map_or(0, Iterator::count), count);
            let colors = reader.read_colors(0).map(|c| c.into_rgba_u8().count());
            assert_eq!(colors, Some(count));
            let indices: Vec<u32> = reader
                .read_indices()
                .map(|i| i.into_u32().collect())
                .unwrap_or_default();
            assert!(!indices.is_empty() && indices.len().is_multiple_of(3));
            assert!(
                indices.iter().all(|&i| (i as usize) < count),
                "index out of range"
            );
        }
    }
    let nodes: Vec<gltf::Node> = doc.nodes().collect();
    let in_scene = scene_nodes(&doc);
    let scene_ids: BTreeSet<usize> = in_scene.iter().map(|(n, _)| n.index()).collect();
    let mut instances = 0u64;
    let mut tri_highest = 0u64;
    let mut tri_all = 0u64;
    let mut kinds = BTreeSet::new();
    let mut furniture_meshes = BTreeSet::new();
    let mut furniture_nodes = 0usize;
    let rooms: BTreeMap<u32, &portico_generator::Room> =
        b.rooms.iter().map(|r| (r.id, r)).collect();
    for (node, world) in &in_scene {
        let Some(mesh) = node.mesh() else {
            continue;
        };
        instances += 1;
        let top = triangle_count(&mesh);
        tri_highest += top;
        tri_all += top;
        let extras = extras_of(node);
        let kind = extras["kind"].as_str().unwrap_or("").to_owned();
        assert!(
            extras["storey"].is_u64(),
            "node {} has no storey",
            node.index()
        );
        match kind.as_str() {
            "wall" | "floor" | "ceiling" => {
                assert_eq!(
                    extras["occluder"],
                    Value::Bool(true),
                    "{kind} not an occluder"
                );
                assert!(node.extension_value("MSFT_lod").is_none());
            }
            "furniture" => {
                assert_eq!(extras["occluder"], Value::Bool(false));
                assert!(extras["type"].is_string());
                assert!(extras["room"].is_string());
                furniture_nodes += 1;
                furniture_meshes.insert(mesh.index());
                let id = extras["room_id"]
                    .as_u64()
                    .and_then(|v| u32::try_from(v).ok());
                let room = id.and_then(|i| rooms.get(&i));
                let Some(room) = room else {
                    panic!("furniture node {} has no known room", node.index());
                };
                assert_eq!(extras["room"].as_str(), Some(room.kind.name()));
                for k in 0..3 {
                    let inside = world[k] >= room.min[k] - 0.05 && world[k] <= room.max[k] + 0.05;
                    assert!(
                        inside,
                        "{} at {world:?} outside room {room:?}",
                        extras["type"]
                    );
                }
                tri_all += check_lod_chain(node, &nodes, &scene_ids, top);
            }
            other => panic!("node {} has unknown kind {other:?}", node.index()),
        }
        kinds.insert(kind);
    }
    assert_eq!(instances, b.stats.instances);
    assert_eq!(tri_highest, b.stats.triangles_highest);
    assert_eq!(tri_all, b.stats.triangles_all_lods);
    for k in ["wall", "floor", "ceiling", "furniture"] {
        assert!(kinds.contains(k), "no {k} nodes");
    }
    assert!(
        furniture_meshes.len() * 2 < furniture_nodes,
        "furniture meshes are not shared"
    );
}

/// Checks an instance's `MSFT_lod` chain and returns the triangles of its lower LODs.
fn check_lod_chain(
    node: &gltf::Node,
    nodes: &[gltf::Node],
    scene_ids: &BTreeSet<usize>,
    top: u64,
) -> u64 {
    let Some(ext) = node.extension_value("MSFT_lod") else {
        return 0;
    };
    let ids: Vec<usize> = ext["ids"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(Value::as_u64)
                .map(|v| v as usize)
                .collect()
        })
        .unwrap_or_default();
    assert!(!ids.is_empty(), "empty MSFT_lod on node {}", node.index());
    let mut previous = top;
    let mut total = 0;
    for id in ids {
        let Some(lod) = nodes.get(id) else {
            panic!("MSFT_lod id {id} does not exist");
        };
        assert!(
            !scene_ids.contains(&id),
            "LOD node {id} is part of the scene tree"
        );
        let Some(mesh) = lod.mesh() else {
            panic!("LOD node {id} has no mesh");
        };
        let t = triangle_count(&mesh);
        assert!(
            t * 2 <= previous,
            "LOD {id}: {t} triangles after {previous}"
        );
        previous = t;
        total += t;
    }
    assert!(previous <= 100, "lowest LOD has {previous} triangles");
    total
}

/// World-space AABBs of every triangle of occluder nodes.
fn occluder_triangles(b: &Building) -> Vec<([f32; 3], [f32; 3])> {
    let (doc, buffers, _) = match gltf::import_slice(&b.glb) {
        Ok(x) => x,
        Err(e) => panic!("cannot import: {e}"),
    };
    let mut out = Vec::new();
    for (node, world) in scene_nodes(&doc) {
        let (Some(mesh), true) = (
            node.mesh(),
            extras_of(&node)["occluder"] == Value::Bool(true),
        ) else {
            continue;
        };
        let (_, rotation, _) = node.transform().decomposed();
        assert_eq!(
            rotation,
            [0.0, 0.0, 0.0, 1.0],
            "structure must be axis-aligned"
        );
        for prim in mesh.primitives() {
            let reader = prim.reader(|buf| buffers.get(buf.index()).map(|d| &d.0[..]));
            let pos: Vec<[f32; 3]> = reader
                .read_positions()
                .map(Iterator::collect)
                .unwrap_or_default();
            let idx: Vec<u32> = reader
                .read_indices()
                .map(|i| i.into_u32().collect())
                .unwrap_or_default();
            for t in idx.chunks(3) {
                let mut min = [f32::MAX; 3];
                let mut max = [f32::MIN; 3];
                for &i in t {
                    for k in 0..3 {
                        let v = pos[i as usize][k] + world[k];
                        min[k] = min[k].min(v);
                        max[k] = max[k].max(v);
                    }
                }
                out.push((min, max));
            }
        }
    }
    out
}

fn overlaps(a: ([f32; 3], [f32; 3]), b: ([f32; 3], [f32; 3])) -> bool {
    (0..3).all(|k| a.0[k] < b.1[k] && b.0[k] < a.1[k])
}

/// The occluder triangle (as its bounding box) that fills an opening, if any: the opening's
/// box shrunk 1 cm along its width and height, so the jambs and lintel do not count, and grown
/// 1 cm across its thinnest axis (the wall's or slab's thickness), so the flat faces of an
/// uncut wall or slab would.
fn filling(
    tris: &[([f32; 3], [f32; 3])],
    d: &portico_generator::Door,
) -> Option<([f32; 3], [f32; 3])> {
    let size: Vec<f32> = (0..3).map(|k| d.max[k] - d.min[k]).collect();
    let thin = (0..3).min_by(|&a, &b| size[a].total_cmp(&size[b])).unwrap();
    let mut inner = (d.min.map(|v| v + 0.01), d.max.map(|v| v - 0.01));
    inner.0[thin] = d.min[thin] - 0.01;
    inner.1[thin] = d.max[thin] + 0.01;
    tris.iter().copied().find(|t| overlaps(*t, inner))
}

/// No occluder geometry inside any door or stair opening, but occluders right around each.
fn check_openings_are_gaps(b: &Building) {
    let tris = occluder_triangles(b);
    assert!(!tris.is_empty());
    for d in &b.doors {
        let blocking = filling(&tris, d);
        assert!(blocking.is_none(), "{d:?} is filled by {blocking:?}");
        let outer = (d.min.map(|v| v - 0.02), d.max.map(|v| v + 0.02));
        assert!(
            tris.iter().any(|t| overlaps(*t, outer)),
            "{d:?} is not in a wall or slab"
        );
        // The check sees a face across the opening: an uncut wall's triangle on either side.
        let thin = (0..3)
            .min_by(|&a, &b| (d.max[a] - d.min[a]).total_cmp(&(d.max[b] - d.min[b])))
            .unwrap();
        for side in [d.min[thin], d.max[thin]] {
            let (mut lo, mut hi) = (d.min, d.max);
            lo[thin] = side;
            hi[thin] = side;
            assert!(
                filling(&[(lo, hi)], d).is_some(),
                "{d:?}: a face is not seen"
            );
        }
    }
}
