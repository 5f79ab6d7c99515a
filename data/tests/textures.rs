//! Textures from real files: glTF's base-colour texture in its three containers (assimp's
//! BoxTextured sample, from the `assimp-testmodels` package CI installs), OBJ's `map_Kd` JPEGs
//! (assimp's spider), a missing image, and the database's mip segments.

use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::format::SegmentKind;
use portico_data::import::import_file;
use portico_data::texture::{PART_BYTES, TexelFormat, Wrap, decode_segment};
use std::path::{Path, PathBuf};

mod common;

const MODELS: &str = "/usr/share/assimp/models";

fn model(rel: &str) -> PathBuf {
    let p = Path::new(MODELS).join(rel);
    assert!(
        p.exists(),
        "{} is missing: install the assimp-testmodels package",
        p.display()
    );
    p
}

#[test]
fn box_textured_imports_its_texture_in_all_three_containers() {
    for rel in [
        "glTF2/BoxTextured-glTF/BoxTextured.gltf",
        "glTF2/BoxTextured-glTF-Binary/BoxTextured.glb",
        "glTF2/BoxTextured-glTF-Embedded/BoxTextured.gltf",
    ] {
        let m = import_file(&model(rel)).unwrap();
        assert!(m.warnings.is_empty(), "{rel}: {:?}", m.warnings);
        assert_eq!(m.textures.len(), 1, "{rel}");
        let t = &m.textures[0];
        assert_eq!((t.width, t.height, t.rgba.len()), (211, 211, 211 * 211 * 4));
        // The .gltf sample's sampler says MIRRORED_REPEAT along s, CLAMP_TO_EDGE along t; the
        // other two say REPEAT.
        let want = if rel.ends_with("-glTF/BoxTextured.gltf") {
            [Wrap::Mirror, Wrap::Clamp]
        } else {
            [Wrap::Repeat; 2]
        };
        assert_eq!(t.wrap, want, "{rel}");
        assert_eq!(m.materials[1].texture, Some(0), "{rel}");
        assert_eq!(m.defs.len(), 1);
        let mesh = &m.defs[0].lods[0];
        assert_eq!(mesh.uvs.len(), mesh.vertices.len(), "{rel}");
        // Its coordinates run to 6 along u: the mirrored repeat is part of the sample.
        assert!(
            mesh.uvs.iter().flatten().all(|x| (0.0..=6.0).contains(x)),
            "{rel}"
        );
        assert_eq!(mesh.uv_span(), 6.0, "{rel}");
    }
}

#[test]
fn a_missing_image_is_a_warning_and_the_box_keeps_its_colour() {
    let dir = tempfile::tempdir().unwrap();
    let src = model("glTF2/BoxTextured-glTF");
    for f in ["BoxTextured.gltf", "BoxTextured0.bin"] {
        std::fs::copy(src.join(f), dir.path().join(f)).unwrap();
    }
    let m = import_file(&dir.path().join("BoxTextured.gltf")).unwrap();
    assert!(m.textures.is_empty());
    assert_eq!(m.materials[1].texture, None);
    assert!(!m.defs[0].lods[0].has_uvs());
    assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
    assert!(
        m.warnings[0].contains("CesiumLogoFlat.png")
            && m.warnings[0].contains("not found")
            && m.warnings[0].contains("drawn in its colour"),
        "{}",
        m.warnings[0]
    );
}

#[test]
fn the_spider_keeps_its_jpeg_maps() {
    let m = import_file(&model("OBJ/spider.obj")).unwrap();
    // The library names its maps Windows-style (`map_Kd .\\SpiderTex.jpg`).
    let names: Vec<&str> = m.textures.iter().map(|t| t.name.as_str()).collect();
    assert!(names.contains(&".\\SpiderTex.jpg"), "{names:?}");
    assert!(names.contains(&".\\drkwood2.jpg"), "{names:?}");
    // No map is lost (a spider has no storeys to tell its unit by: those warnings name the
    // options, and nothing else is said).
    assert!(
        m.warnings
            .iter()
            .all(|w| w.contains("--units") || w.contains("--up")),
        "{:?}",
        m.warnings
    );
    let textured = m
        .defs
        .iter()
        .filter(|d| m.materials[d.material as usize].texture.is_some())
        .collect::<Vec<_>>();
    assert!(!textured.is_empty());
    for d in textured {
        let mesh = &d.lods[0];
        assert_eq!(mesh.uvs.len(), mesh.vertices.len(), "{}", d.name);
    }
    // Every map was found: one texture per distinct map_Kd.
    assert_eq!(m.textures.len(), 5, "{names:?}");
}

#[test]
fn a_built_database_holds_each_texture_coarse_first_as_whole_mip_chains() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("box.portico");
    let m = import_file(&model("glTF2/BoxTextured-glTF-Binary/BoxTextured.glb")).unwrap();
    build(
        m,
        &out,
        &BuildOptions {
            no_cells: true,
            no_hierarchy: true,
            ..Default::default()
        },
        &Quiet,
    )
    .unwrap();
    let db = Database::open(&out).unwrap();
    let h = db.header();
    assert_eq!(h.textures.len(), 1);
    let t = &h.textures[0];
    // 211 texels: levels 211, 105, 52, 26, 13, 6, 3, 1. Levels of at most 64 texels are the
    // coarse segment; 105 and 211 get a segment each, holding every coarser level too.
    let shapes: Vec<(u32, u32)> = t.segments.iter().map(|s| (s.width, s.levels)).collect();
    assert_eq!(shapes, vec![(52, 6), (105, 7), (211, 8)]);
    for s in &t.segments {
        let entry = db.segments()[s.segment as usize];
        assert_eq!(SegmentKind::from_u16(entry.kind), Some(SegmentKind::Mips));
        let bytes = db.texture_segment(s).unwrap();
        let v = decode_segment(&bytes).unwrap();
        assert_eq!((v.width, v.levels), (s.width, s.levels));
        assert_eq!(v.texels.len() as u64, s.texel_bytes());
        // Coded: far fewer bytes than the texels they give.
        assert!(
            bytes.len() as u64 * 2 < s.texel_bytes(),
            "{} bytes",
            bytes.len()
        );
    }
    // What a client's cache is charged for them: what its GPU holds, not the coded bytes.
    // With BC textures, the coarse segment (52 texels: whole 4 × 4 blocks) as BC blocks; 105
    // and 211 texels are not whole blocks, so they stay RGBA8.
    let wire: Vec<u64> = db.segments().iter().map(|e| e.length).collect();
    let rgba = h.cache_charges(&wire, TexelFormat::Rgba8);
    let block = h.cache_charges(&wire, TexelFormat::Block);
    for s in &t.segments {
        let (r, b) = (rgba[s.segment as usize], block[s.segment as usize]);
        assert_eq!(r, s.texel_bytes());
        assert_eq!(b, s.gpu_bytes(TexelFormat::Block));
        if s.width == 52 {
            assert!(b * 4 <= r, "{b} of {r}");
        } else {
            assert_eq!(b, r, "{} texels", s.width);
        }
    }
    // The coarse segment is small: what arrives with the first geometry.
    let coarse = db.segment(t.segments[0].segment).unwrap().len();
    assert!(coarse < 8 * 1024, "{coarse}");
    let lods = &h.objects[0].lods;
    assert!(lods[0].uv, "the finest LOD carries coordinates");
    assert!(h.objects[0].uv_span > 0.5);
    assert_eq!(h.materials[h.objects[0].material as usize].texture, Some(0));
    // `portico inspect` names it, with its size and what its segments weigh.
    let st = portico_data::stats::stats(&db);
    assert_eq!(st.texture_list.len(), 1);
    assert_eq!(
        (st.texture_list[0].width, st.texture_list[0].segments),
        (211, 3)
    );
    assert!(
        st.to_text().contains(&st.texture_list[0].name),
        "{}",
        st.to_text()
    );
    let avg = t.average;
    assert!(avg.iter().take(3).all(|c| (0.0..=1.0).contains(c)));
}

/// Prefetch answers list each texture coarse first, with the first object that needs it, before
/// any finer level of that texture and before the finer LODs of the objects drawn with it; a
/// texture's finer segments come after its coarse one, never instead of it.
#[test]
fn prefetch_brings_coarse_mips_with_the_geometry_that_needs_them() {
    use portico_protocol::{NeedKind, Policy, RangeCull};
    let p = common::prefetcher_for(5, 1, true, &BuildOptions::default(), None);
    let h = p.database().header();
    assert_eq!(h.textures.len(), 4, "brick, wood, carpet, tiles");
    // A segment or one of its parts: the texture, the level and the part.
    let texture_of_segment = |s: u32| {
        h.textures.iter().enumerate().find_map(|(t, r)| {
            r.segments.iter().enumerate().find_map(|(k, m)| {
                m.ids()
                    .position(|id| id == s)
                    .map(|part| (t, k, part as u32))
            })
        })
    };
    // The finer levels of the generator's 512² textures are longer than a part: cut, every
    // piece at most a part long, and joined they decode to the level they were cut from.
    let cut: Vec<_> = h
        .textures
        .iter()
        .flat_map(|t| &t.segments)
        .filter(|s| s.parts > 0)
        .collect();
    assert!(!cut.is_empty(), "no texture segment longer than a part");
    for e in p.database().segments() {
        if matches!(
            SegmentKind::from_u16(e.kind),
            Some(SegmentKind::Mips | SegmentKind::MipPart)
        ) {
            assert!(
                e.length <= PART_BYTES as u64,
                "segment {}: {} bytes",
                e.id,
                e.length
            );
        }
    }
    for s in &cut {
        let whole = p.database().texture_segment(s).unwrap();
        assert!(whole.len() > PART_BYTES);
        let v = decode_segment(&whole).unwrap();
        assert_eq!((v.width, v.height, v.levels), (s.width, s.height, s.levels));
    }
    let mut parts_seen = 0;
    let g = p.graph().unwrap();
    // A screen large enough to want the finest levels, which are cut into parts.
    let policy = Policy {
        read_bytes: 1 << 30,
        range_cull: RangeCull::Any,
        screen: [3840, 2160],
        ..Policy::default()
    };
    let mut mips_seen = 0;
    for c in g.cells.iter().filter(|c| c.live) {
        let mid = glam::Vec3::from(c.bounds.min).lerp(glam::Vec3::from(c.bounds.max), 0.5);
        let obs = common::observer(mid, [1.0, 0.0, 0.0]);
        let a = p.answer(&obs, &policy, &Default::default()).unwrap();
        let mut first_at = std::collections::HashMap::new();
        for (i, item) in a.items.iter().enumerate() {
            if item.kind != NeedKind::Mips {
                continue;
            }
            mips_seen += 1;
            let (t, k, part) = texture_of_segment(item.segment).expect("a texture's segment");
            assert_eq!(item.lod as usize, k, "the item names its level");
            // A part comes right after the piece before it.
            if part > 0 {
                parts_seen += 1;
                assert_eq!(
                    a.items[i - 1].segment,
                    item.segment - 1,
                    "part {part} out of order"
                );
            }
            // What the segment weighs on the wire: its coded size.
            assert_eq!(
                item.bytes,
                p.database().segments()[item.segment as usize].length
            );
            // The first segment of each texture listed is its coarse one.
            let first = *first_at.entry(t).or_insert((i, k));
            // Held, a head's parts are held too: none of them is listed again.
            if part == 0 && h.textures[t].segments[k].parts > 0 {
                let group: std::collections::HashSet<u32> =
                    h.textures[t].segments[k].ids().collect();
                let again = p.answer(&obs, &policy, &group).unwrap();
                assert!(again.items.iter().all(|i| !group.contains(&i.segment)));
            }
            assert_eq!(
                first.1, 0,
                "texture {t}: segment {k} listed before the coarse one"
            );
        }
        // Every textured object's coarse texture comes before its LODs finer than the coarsest
        // with coordinates (which it follows).
        for item in a.items.iter().filter(|i| i.kind == NeedKind::Geometry) {
            let owner = h
                .instances
                .iter()
                .find(|inst| h.lods_of(inst).iter().any(|l| l.segment == item.segment));
            let Some(inst) = owner else { continue };
            let coarsest_uv = h.lods_of(inst).iter().rposition(|l| l.uv);
            if coarsest_uv.is_none_or(|c| item.lod as usize >= c) {
                continue;
            }
            if let Some(t) = h.materials[inst.material as usize].texture {
                let at = a
                    .items
                    .iter()
                    .position(|i| i.segment == item.segment)
                    .unwrap();
                let coarse = first_at.get(&(t as usize)).map(|f| f.0);
                assert!(
                    coarse.is_some_and(|c| c < at),
                    "texture {t}'s coarse segment after a finer LOD of {}",
                    inst.name
                );
            }
        }
    }
    assert!(mips_seen > 0, "no answer asked for a texture");
    assert!(parts_seen > 0, "no answer asked for a part");
}

/// Hostile or careless names: a map that names a directory, an image outside the model's
/// directory, and textures sharing one image (decoded once).
#[test]
fn odd_map_names_warn_and_shared_images_decode_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("a.obj"),
        "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\n",
    )
    .unwrap();
    for name in ["..", ".", "/"] {
        std::fs::write(
            d.join("a.mtl"),
            format!("newmtl m\nKd 1 1 1\nmap_Kd {name}\n"),
        )
        .unwrap();
        let m = import_file(&d.join("a.obj")).unwrap();
        assert!(m.textures.is_empty(), "map_Kd {name}");
        assert!(
            m.warnings.iter().any(|w| w.contains("map_Kd")),
            "map_Kd {name}: {:?}",
            m.warnings
        );
    }
    let src = model("glTF2/BoxTextured-glTF");
    let sub = d.join("model");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::copy(src.join("BoxTextured0.bin"), sub.join("BoxTextured0.bin")).unwrap();
    std::fs::copy(src.join("CesiumLogoFlat.png"), d.join("CesiumLogoFlat.png")).unwrap();
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(src.join("BoxTextured.gltf")).unwrap()).unwrap();
    json["images"][0]["uri"] = "../CesiumLogoFlat.png".into();
    std::fs::write(sub.join("up.gltf"), serde_json::to_vec(&json).unwrap()).unwrap();
    let m = import_file(&sub.join("up.gltf")).unwrap();
    assert!(m.textures.is_empty());
    assert!(
        m.warnings[0].contains("outside the model's directory"),
        "{:?}",
        m.warnings
    );
    // Three textures, two materials, one image with one sampler: decoded once.
    std::fs::copy(
        src.join("CesiumLogoFlat.png"),
        sub.join("CesiumLogoFlat.png"),
    )
    .unwrap();
    json["images"][0]["uri"] = "CesiumLogoFlat.png".into();
    let tex = json["textures"][0].clone();
    json["textures"] = serde_json::json!([tex.clone(), tex.clone(), tex]);
    let mut second = json["materials"][0].clone();
    second["pbrMetallicRoughness"]["baseColorTexture"]["index"] = 2.into();
    json["materials"].as_array_mut().unwrap().push(second);
    std::fs::write(sub.join("shared.gltf"), serde_json::to_vec(&json).unwrap()).unwrap();
    let m = import_file(&sub.join("shared.gltf")).unwrap();
    assert_eq!(m.textures.len(), 1);
    assert_eq!(
        (m.materials[1].texture, m.materials[2].texture),
        (Some(0), Some(0))
    );
}
