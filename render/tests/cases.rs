//! The material cases of `data/tests/cases/textures/` drawn on the test machine's adapter
//! (llvmpipe in CI), as the client draws them: baked lighting in an emissive texture shows,
//! an unlit floor keeps its colour, single-sided back faces never bleed through, and texture
//! coordinates placed in world units draw the same picture as ones near zero.

use glam::{Mat4, Vec3};
use image::RgbaImage;
use portico_data::geometry::{Mesh, Vertex, encode_geometry};
use portico_data::import::import_file;
use portico_data::model::{Model, Surface};
use portico_data::texture::{average_color, cut_segments, mip_chain, to_linear, to_srgb};
use portico_render::{Camera, Draw, GpuMesh, GpuTexture, Renderer};
use std::path::Path;

const W: u32 = 160;
const H: u32 = 120;

fn case(rel: &str) -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data/tests/cases/textures")
        .join(rel);
    import_file(&path).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn renderer(towards_light: Vec3, ambient: f32) -> Renderer {
    let mut r = Renderer::with_samples(W, H, Some(1))
        .unwrap_or_else(|e| panic!("no wgpu adapter/device (CI has llvmpipe): {e}"));
    r.set_light(towards_light, ambient);
    r
}

/// From a person's eye in the west room (x 0.2..4.9, z 0.2..7.8) towards `target`.
fn camera(eye: Vec3, target: Vec3) -> Camera {
    Camera {
        eye,
        target,
        up: Vec3::Y,
        fovy: 60f32.to_radians(),
        near: 0.05,
        far: 50.0,
    }
}

/// Every instance of `m` drawn as the client draws it (finest LOD, finest mip chain, the
/// material's alpha and surface), in the instances' order or reversed.
fn draw(r: &mut Renderer, m: &Model, cam: &Camera, reversed: bool) -> RgbaImage {
    let meshes: Vec<GpuMesh> = m
        .defs
        .iter()
        .map(|d| r.upload(&encode_geometry(&d.lods[0])).unwrap())
        .collect();
    let textures: Vec<GpuTexture> = m
        .textures
        .iter()
        .map(|t| {
            let chain = mip_chain(t.width, t.height, &t.rgba);
            let segs = cut_segments(t.width, t.height, &chain);
            r.upload_texture(&segs.last().unwrap().3, t.wrap).unwrap()
        })
        .collect();
    let mut draws: Vec<Draw<'_>> = m
        .instances
        .iter()
        .map(|i| {
            let mat = &m.materials[i.material as usize];
            let mut d = Draw::new(&meshes[i.def as usize], i.transform, [1.0; 4]);
            d.texture = mat.texture.map(|t| &textures[t as usize]);
            d.alpha = mat.alpha;
            d.surface = mat.surface();
            d
        })
        .collect();
    if reversed {
        draws.reverse();
    }
    r.render(cam, &draws).unwrap();
    r.read_pixels().unwrap()
}

/// The middle `frac` of the picture (both ways), averaged in linear light, as sRGB bytes.
fn middle(img: &RgbaImage, frac: f32) -> [u8; 3] {
    let (x0, x1) = (
        (W as f32 * (0.5 - frac / 2.0)) as u32,
        (W as f32 * (0.5 + frac / 2.0)) as u32,
    );
    let (y0, y1) = (
        (H as f32 * (0.5 - frac / 2.0)) as u32,
        (H as f32 * (0.5 + frac / 2.0)) as u32,
    );
    let mut sum = [0.0f64; 3];
    let mut n = 0.0;
    for y in y0..y1 {
        for x in x0..x1 {
            let p = img.get_pixel(x, y).0;
            for c in 0..3 {
                sum[c] += to_linear(p[c]) as f64;
            }
            n += 1.0;
        }
    }
    sum.map(|s| to_srgb((s / n) as f32))
}

fn near(a: [u8; 3], b: [u8; 3], tolerance: u8) -> bool {
    (0..3).all(|c| a[c].abs_diff(b[c]) <= tolerance)
}

/// A texture's average colour as sRGB bytes.
fn average_of(m: &Model, material: &str) -> [u8; 3] {
    let mat = m.materials.iter().find(|x| x.name == material).unwrap();
    let t = &m.textures[mat.texture.unwrap() as usize];
    let a = average_color(&t.rgba);
    [to_srgb(a[0]), to_srgb(a[1]), to_srgb(a[2])]
}

const EYE: Vec3 = Vec3::new(2.5, 1.6, 4.0);

#[test]
fn baked_lighting_shows_and_unlit_floors_keep_their_colour() {
    let m = case("emissive/house_emissive.gltf");
    // A grazing light: a lit floor would be far darker than its texture.
    let mut r = renderer(Vec3::new(1.0, 0.1, 0.3), 0.2);
    // The west wall: black base colour, its baked lighting in the emissive texture.
    let wall = middle(
        &draw(&mut r, &m, &camera(EYE, Vec3::new(0.2, 1.6, 4.0)), false),
        0.5,
    );
    let want = average_of(&m, "baked_wall_emissive");
    assert!(
        near(wall, want, 24),
        "wall drawn {wall:?}, its baked texture {want:?}"
    );
    // The floor: unlit, so exactly its texture.
    // (Beside the table, which stands under the usual eye.)
    let down = camera(Vec3::new(1.2, 1.6, 6.0), Vec3::new(1.2, 0.0, 6.01));
    let floor = middle(&draw(&mut r, &m, &down, false), 0.5);
    let want = average_of(&m, "baked_floor_unlit");
    assert!(
        near(floor, want, 24),
        "floor drawn {floor:?}, its texture {want:?}"
    );
    // The inner wall's emissive factor alone, over black: (1, 0.6, 0.2) whatever the light.
    let inner = middle(
        &draw(
            &mut r,
            &m,
            &camera(Vec3::new(2.5, 1.6, 2.0), Vec3::new(4.9, 1.6, 2.0)),
            false,
        ),
        0.3,
    );
    let want = [255, to_srgb(0.6), to_srgb(0.2)];
    assert!(
        near(inner, want, 4),
        "inner wall drawn {inner:?}, emissive {want:?}"
    );
}

#[test]
fn back_faces_of_single_sided_materials_never_show() {
    let m = case("back-faces/house_backfaces.gltf");
    let mut r = renderer(Vec3::Z, 1.0);
    let cam = camera(EYE, Vec3::new(2.5, 1.6, 0.0));
    // Each reversed copy drawn first: without culling it wins every depth tie.
    for reversed in [false, true] {
        let img = draw(&mut r, &m, &cam, reversed);
        let blue = img
            .pixels()
            .filter(|p| p.0[2] as i32 > p.0[0] as i32 + 20)
            .count();
        assert_eq!(blue, 0, "back colour shows (reversed order: {reversed})");
        let wall = middle(&img, 0.3);
        let white = [to_srgb(0.85), to_srgb(0.85), to_srgb(0.8)];
        assert!(
            near(wall, white, 3),
            "south wall {wall:?}, its front colour {white:?}"
        );
    }
}

#[test]
fn a_mirroring_transform_keeps_the_front_of_a_single_sided_surface() {
    let mut r = renderer(Vec3::Z, 1.0);
    r.set_clear(portico_render::wgpu::Color::BLACK);
    // A quad facing +z (counter-clockwise seen from +z).
    let v = |x: f32, y: f32| Vertex::new([x, y, 0.0], [0.0, 0.0, 1.0], [1.0; 4]);
    let quad = Mesh {
        vertices: vec![v(-1.0, -1.0), v(1.0, -1.0), v(1.0, 1.0), v(-1.0, 1.0)],
        indices: vec![0, 1, 2, 0, 2, 3],
        uvs: Vec::new(),
    };
    let gpu = r.upload(&encode_geometry(&quad)).unwrap();
    let single = Surface {
        double_sided: false,
        ..Surface::default()
    };
    let centre = |r: &mut Renderer, t: Mat4, eye: Vec3| {
        let mut d = Draw::new(&gpu, t, [1.0; 4]);
        d.surface = single;
        r.render(&camera(eye, Vec3::ZERO), &[d]).unwrap();
        r.read_pixels().unwrap().get_pixel(W / 2, H / 2).0[0]
    };
    let (front, back) = (Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.0, 0.0, -2.0));
    assert_eq!(centre(&mut r, Mat4::IDENTITY, front), 255);
    assert_eq!(centre(&mut r, Mat4::IDENTITY, back), 0);
    // A two-sided surface is drawn, and lit, from behind too.
    let mut d = Draw::new(&gpu, Mat4::IDENTITY, [1.0; 4]);
    d.surface = Surface::default();
    r.render(&camera(back, Vec3::ZERO), &[d]).unwrap();
    assert_eq!(r.read_pixels().unwrap().get_pixel(W / 2, H / 2).0[0], 255);
    // Mirrored in x: the triangles wind the other way, and glTF says the front stays +z.
    let mirror = Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
    assert_eq!(centre(&mut r, mirror, front), 255);
    assert_eq!(centre(&mut r, mirror, back), 0);
    // Mirrored into the mesh itself, as a flattened build bakes it: still the same front.
    let baked = r
        .upload(&encode_geometry(&quad.transformed(&mirror)))
        .unwrap();
    let baked_centre = |r: &mut Renderer, eye: Vec3| {
        let mut d = Draw::new(&baked, Mat4::IDENTITY, [1.0; 4]);
        d.surface = single;
        r.render(&camera(eye, Vec3::ZERO), &[d]).unwrap();
        r.read_pixels().unwrap().get_pixel(W / 2, H / 2).0[0]
    };
    assert_eq!(baked_centre(&mut r, front), 255);
    assert_eq!(baked_centre(&mut r, back), 0);
}

#[test]
fn world_unit_texture_coordinates_draw_the_same_picture_as_near_ones() {
    let (far, near) = (
        case("far-uv/house_far_uv.gltf"),
        case("far-uv/house_near_uv.gltf"),
    );
    let mut r = renderer(Vec3::new(0.3, 1.0, 0.5), 0.4);
    for target in [Vec3::new(2.5, 1.2, 0.0), Vec3::new(2.5, 0.0, 3.0)] {
        let cam = camera(EYE, target);
        let (a, b) = (
            draw(&mut r, &far, &cam, false),
            draw(&mut r, &near, &cam, false),
        );
        let diff: u64 = a
            .as_raw()
            .iter()
            .zip(b.as_raw())
            .map(|(x, y)| x.abs_diff(*y) as u64)
            .sum();
        let mean = diff as f64 / a.as_raw().len() as f64;
        assert!(
            mean < 2.0,
            "towards {target}: mean difference {mean:.2} levels"
        );
    }
}
