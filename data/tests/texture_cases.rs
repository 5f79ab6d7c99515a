//! The texture and material cases (`tests/cases/textures/`, each folder's right behaviour in
//! its README) imported: every image found, decoded and sized as the README says, and the
//! materials' emissive, unlit, sides and transparency read. How they look drawn is
//! `render/tests/cases.rs`.

use portico_data::import::import_file;
use portico_data::model::{Model, TextureRole};
use portico_data::texture::{AlphaMode, MAX_SIZE};
use std::path::{Path, PathBuf};

fn case(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/cases/textures")
        .join(rel)
}

fn import(rel: &str) -> Model {
    import_file(&case(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The material named `name` (the first of that name).
fn material<'a>(m: &'a Model, name: &str) -> &'a portico_data::model::Material {
    m.materials
        .iter()
        .find(|x| x.name == name)
        .unwrap_or_else(|| panic!("no material '{name}'"))
}

fn texel(m: &Model, texture: u32, x: u32, y: u32) -> [u8; 4] {
    let t = &m.textures[texture as usize];
    let i = ((y * t.width + x) * 4) as usize;
    t.rgba[i..i + 4].try_into().unwrap()
}

fn warned(m: &Model, all: &[&str]) -> bool {
    m.warnings.iter().any(|w| all.iter().all(|s| w.contains(s)))
}

#[test]
fn tga_maps_decode_by_their_extension() {
    let m = import("tga-maps/house_tga.obj");
    for name in ["wall", "floor", "inner", "furniture"] {
        assert!(
            material(&m, name).texture.is_some(),
            "{name}: {:?}",
            m.warnings
        );
    }
    assert!(!warned(&m, &["not an image"]), "{:?}", m.warnings);
    // Against the files' own bytes: wall_diff.tga is 24-bit BGR, rows bottom up, so its first
    // pixel is the image's bottom-left texel.
    let raw = std::fs::read(case("tga-maps/textures/wall_diff.tga")).unwrap();
    let (w, h) = (
        u16::from_le_bytes([raw[12], raw[13]]) as u32,
        u16::from_le_bytes([raw[14], raw[15]]) as u32,
    );
    let wall = material(&m, "wall").texture.unwrap();
    let t = &m.textures[wall as usize];
    assert_eq!((t.width, t.height), (w, h));
    assert_eq!(texel(&m, wall, 0, h - 1), [raw[20], raw[19], raw[18], 255]);
    // inner_diff.tga is 32-bit BGRA stored top down, its alpha replaced by mask.tga (8-bit
    // grey, bottom up): a cut-out.
    let raw = std::fs::read(case("tga-maps/textures/inner_diff.tga")).unwrap();
    let mask = std::fs::read(case("tga-maps/textures/mask.tga")).unwrap();
    let inner = material(&m, "inner");
    assert_eq!(inner.alpha, AlphaMode::Mask(0.5));
    let px = texel(&m, inner.texture.unwrap(), 0, 0);
    assert_eq!(&px[..3], &[raw[20], raw[19], raw[18]]);
    let last_row_first = 18 + 255 * 256; // the mask's top-left texel
    assert_eq!(px[3], mask[last_row_first]);
    // The RLE-coded floor decodes to a picture, not one colour.
    let floor = &m.textures[material(&m, "floor").texture.unwrap() as usize];
    assert!(floor.rgba.chunks_exact(4).any(|p| p != &floor.rgba[..4]));
}

#[test]
fn names_that_differ_in_case_are_found_with_a_warning() {
    for file in ["name-case/house_case.obj", "name-case/house_case.gltf"] {
        let m = import(file);
        for name in ["wall", "floor", "inner"] {
            assert!(
                material(&m, name).texture.is_some(),
                "{file} {name}: {:?}",
                m.warnings
            );
        }
        assert!(
            warned(&m, &["Brick.JPG", "Textures/brick.jpg", "case"]),
            "{file}: {:?}",
            m.warnings
        );
        // The brick JPEG is mostly brick red.
        let avg = portico_data::texture::average_color(
            &m.textures[material(&m, "wall").texture.unwrap() as usize].rgba,
        );
        assert!(avg[0] > 2.0 * avg[2], "{avg:?}");
    }
    // OAK.JPG is oak.jpeg: another name, not another case. Still missing, and said so.
    let m = import("name-case/house_case.obj");
    assert!(material(&m, "furniture").texture.is_none());
    assert!(warned(&m, &["OAK.JPG", "not found"]), "{:?}", m.warnings);
}

#[test]
fn backslashes_in_uris_are_read_as_slashes_with_a_warning() {
    let m = import("uri-backslash/house_backslash.gltf");
    for name in ["wall", "floor", "inner", "furniture"] {
        assert!(
            material(&m, name).texture.is_some(),
            "{name}: {:?}",
            m.warnings
        );
    }
    for uri in [
        "textures\\wall.png",
        ".\\textures\\floor.png",
        "textures\\inner.png",
    ] {
        assert!(
            warned(&m, &[uri, "read as 'textures/"]),
            "{uri}: {:?}",
            m.warnings
        );
    }
    assert_eq!(m.warnings.len(), 3, "{:?}", m.warnings);
}

#[test]
fn any_size_is_read_and_scaled_to_the_texture_limit() {
    let m = import("large/house_8k_16k.gltf");
    let strip = &m.textures[material(&m, "wall").texture.unwrap() as usize];
    let floor = &m.textures[material(&m, "floor").texture.unwrap() as usize];
    assert_eq!((strip.width, strip.height), (MAX_SIZE, MAX_SIZE / 32));
    assert_eq!((floor.width, floor.height), (MAX_SIZE, MAX_SIZE));
    assert!(
        warned(&m, &["strip_16k.png", "16384x512", "4096x128"]),
        "{:?}",
        m.warnings
    );
    assert!(
        warned(&m, &["floor_8k.png", "8192x8192"]),
        "{:?}",
        m.warnings
    );
}

#[test]
fn webp_is_decoded_and_ktx2_leaves_its_material_in_colour_with_a_warning() {
    let m = import("ktx2-webp/house_webp_required.gltf");
    let floor = material(&m, "floor");
    let t = &m.textures[floor.texture.expect("the WebP floor") as usize];
    assert_eq!(t.name, "tex/floor.webp");
    assert_eq!((t.width, t.height), (256, 256));
    // Its picture: the blue floor tiles, as its PNG twin in the other cases.
    let avg = portico_data::texture::average_color(&t.rgba);
    assert!(avg[2] > 2.0 * avg[0] && avg[2] > 0.5, "{avg:?}");
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    let m = import("ktx2-webp/house_ktx2_required.gltf");
    assert!(material(&m, "inner").texture.is_none());
    assert!(material(&m, "wall").texture.is_some());
    assert!(
        warned(
            &m,
            &[
                "material 1 'inner'",
                "KHR_texture_basisu",
                "drawn in its colour"
            ]
        ),
        "{:?}",
        m.warnings
    );
}

/// A real Basis Universal KTX2 (ETC1S, what gltfpack writes) in place of the case's broken
/// one: transcoded and stored like any other texture, its picture the photograph's.
#[test]
fn basis_universal_ktx2_is_transcoded_like_any_other_image() {
    let dir = tempfile::tempdir().unwrap();
    let from = case("ktx2-webp");
    for f in ["house_ktx2_required.gltf", "house_ktx2_required.bin"] {
        std::fs::copy(from.join(f), dir.path().join(f)).unwrap();
    }
    std::fs::create_dir(dir.path().join("tex")).unwrap();
    for f in ["wall.png", "shared.png", "floor.webp", "wall.webp"] {
        std::fs::copy(from.join("tex").join(f), dir.path().join("tex").join(f)).unwrap();
    }
    std::fs::copy(
        from.join("basis/kodim23.ktx2"),
        dir.path().join("tex/inner.ktx2"),
    )
    .unwrap();
    let m = import_file(&dir.path().join("house_ktx2_required.gltf")).unwrap();
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    let inner = material(&m, "inner").texture.expect("the KTX2 texture");
    let t = &m.textures[inner as usize];
    assert_eq!((t.width, t.height), (768, 512));
    let img = image::RgbaImage::from_raw(t.width, t.height, t.rgba.clone()).unwrap();
    let small = image::DynamicImage::ImageRgba8(img)
        .thumbnail_exact(48, 32)
        .to_rgba8();
    let want = image::open(from.join("basis/kodim23_48x32.png"))
        .unwrap()
        .to_rgba8();
    let p = portico_data::texture::psnr(want.as_raw(), small.as_raw());
    eprintln!("kodim23.ktx2 (ETC1S) transcoded: 48x32 average {p:.1} dB against the photograph");
    assert!(p >= 40.0, "{p:.1} dB against the photograph");
}

#[test]
fn emissive_and_unlit_materials_are_read() {
    let m = import("emissive/house_emissive.gltf");
    let wall = material(&m, "baked_wall_emissive");
    assert_eq!(wall.texture_role, TextureRole::Emissive);
    assert!(wall.texture.is_some());
    assert_eq!((wall.emissive, wall.unlit), ([1.0; 3], false));
    let floor = material(&m, "baked_floor_unlit");
    assert_eq!((floor.texture_role, floor.unlit), (TextureRole::Base, true));
    assert_eq!(
        material(&m, "emissive_factor_only").emissive,
        [1.0, 0.6, 0.2]
    );
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
}

#[test]
fn single_sided_materials_say_so_and_obj_ones_are_two_sided() {
    let m = import("back-faces/house_backfaces.gltf");
    assert!(!material(&m, "front_white").double_sided);
    assert!(!material(&m, "back_bluegrey").double_sided);
    let m = import("mtl-tr/house_glass_tr.obj");
    assert!(m.materials.iter().all(|x| x.double_sided));
}

#[test]
fn mtl_tr_is_one_minus_d() {
    let m = import("mtl-tr/house_glass_tr.obj");
    let glass = material(&m, "inner");
    assert_eq!(glass.alpha, AlphaMode::Blend);
    assert!(
        (glass.base_color[3] - 0.2).abs() < 1e-6,
        "{:?}",
        glass.base_color
    );
    assert_eq!(material(&m, "wall").alpha, AlphaMode::Opaque);
    // With both, d wins (3ds Max writes `d 1` and `Tr 0`; here they disagree).
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("b.mtl"),
        "newmtl both\nKd 1 1 1\nd 0.7\nTr 0.5\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("b.obj"),
        "mtllib b.mtl\nusemtl both\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let m = import_file(&dir.path().join("b.obj")).unwrap();
    assert!((material(&m, "both").base_color[3] - 0.7).abs() < 1e-6);
    // `Tr 1` alone would hide the surface: some exporters mean opacity by it.
    std::fs::write(dir.path().join("b.mtl"), "newmtl both\nKd 1 1 1\nTr 1\n").unwrap();
    let m = import_file(&dir.path().join("b.obj")).unwrap();
    assert_eq!(material(&m, "both").alpha, AlphaMode::Opaque);
    assert!(
        warned(&m, &["'both'", "Tr 1", "opaque"]),
        "{:?}",
        m.warnings
    );
}

#[test]
fn far_texture_coordinates_lose_their_whole_number_offset() {
    let far = import("far-uv/house_far_uv.gltf");
    let near = import("far-uv/house_near_uv.gltf");
    for (f, n) in far.defs.iter().zip(&near.defs) {
        let (fu, nu) = (&f.lods[0].uvs, &n.lods[0].uvs);
        assert_eq!(fu.len(), nu.len(), "{}", f.name);
        for (a, b) in fu.iter().zip(nu) {
            // Both near 0: the same picture, up to the far file's own f32 steps (1/128).
            assert!(a[0].abs() < 64.0 && a[1].abs() < 64.0, "{}: {a:?}", f.name);
            let d = [a[0] - b[0], a[1] - b[1]].map(|x| (x - x.round()).abs());
            assert!(
                d[0] <= 1.0 / 128.0 && d[1] <= 1.0 / 128.0,
                "{}: {a:?} {b:?}",
                f.name
            );
        }
    }
}
