//! The renderer on the test machine's adapter (llvmpipe in CI).

use super::*;
use glam::Vec3;

use portico_data::geometry::{
    GEOMETRY_MAGIC, GEOMETRY_U32_INDICES, GEOMETRY_VERSION, GeometryHeader, Mesh, Vertex,
    encode_geometry,
};

const W: u32 = 64;
const H: u32 = 48;
const RED: [f32; 4] = [1.0, 0.0, 0.0, 1.0];
const GREEN: [f32; 4] = [0.0, 1.0, 0.0, 1.0];
const BLUE: [f32; 4] = [0.0, 0.0, 1.0, 1.0];

/// A renderer on the test machine's adapter; failing to get one fails the test.
fn renderer() -> Renderer {
    match Renderer::new(W, H) {
        Ok(r) => r,
        Err(e) => panic!("no wgpu adapter/device (CI has llvmpipe): {e}"),
    }
}

fn camera() -> Camera {
    Camera {
        eye: Vec3::new(0.0, 0.0, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fovy: 60f32.to_radians(),
        near: 0.1,
        far: 100.0,
    }
}

/// A white square of half-size `half` in the plane z = 0, facing +z.
fn square(half: f32) -> Mesh {
    let v = |x: f32, y: f32| Vertex::new([x * half, y * half, 0.0], [0.0, 0.0, 1.0], [1.0; 4]);
    Mesh {
        vertices: vec![v(-1.0, -1.0), v(1.0, -1.0), v(1.0, 1.0), v(-1.0, 1.0)],
        indices: vec![0, 1, 2, 0, 2, 3],
        uvs: Vec::new(),
    }
}

fn at(mesh: &GpuMesh, offset: Vec3, color: [f32; 4]) -> Draw<'_> {
    Draw::new(mesh, Mat4::from_translation(offset), color)
}

/// The pixel a world point projects to.
fn pixel_of(p: Vec3) -> (u32, u32) {
    let ndc = camera().view_proj(W as f32 / H as f32).project_point3(p);
    let x = (ndc.x + 1.0) * 0.5 * W as f32;
    let y = (1.0 - ndc.y) * 0.5 * H as f32;
    (x as u32, y as u32)
}

/// The clear colour as read back (from a frame with nothing in it).
fn sky(r: &mut Renderer) -> image::Rgba<u8> {
    let (_, img) = r.render_to_image(&camera(), &[]).expect("empty frame");
    *img.get_pixel(0, 0)
}

#[test]
fn visible_square_covers_centre_not_corners() {
    let mut r = renderer();
    assert!(!r.adapter_info().is_empty());
    assert_eq!(r.size(), (W, H));
    let sky = sky(&mut r);
    let mesh = r.upload(&encode_geometry(&square(0.5))).expect("upload");
    assert!(mesh.gpu_bytes() > 0);
    assert_eq!((mesh.triangles(), mesh.vertices()), (2, 4));
    assert!(!mesh.wide_indices());
    let (t, img) = r
        .render_to_image(&camera(), &[at(&mesh, Vec3::ZERO, [1.0; 4])])
        .expect("render");
    assert_eq!((t.triangles, t.vertices, t.draws), (2, 4, 1));
    assert!(t.total_s >= t.cpu_submit_s && t.total_s > 0.0);
    assert_ne!(*img.get_pixel(W / 2, H / 2), sky);
    for (x, y) in [(0, 0), (W - 1, 0), (0, H - 1), (W - 1, H - 1)] {
        assert_eq!(*img.get_pixel(x, y), sky, "corner {x},{y}");
    }
}

#[test]
fn uploads_from_another_thread_render() {
    fn shareable<T: Send + Sync>() {}
    shareable::<Renderer>();
    shareable::<GpuMesh>();
    shareable::<Uploader>();
    let mut r = renderer();
    let sky = sky(&mut r);
    let uploader = r.uploader();
    let bytes = encode_geometry(&square(0.5));
    let mesh = std::thread::spawn(move || uploader.upload(&bytes))
        .join()
        .expect("upload thread")
        .expect("upload");
    let (_, img) = r
        .render_to_image(&camera(), &[at(&mesh, Vec3::ZERO, BLUE)])
        .expect("render");
    assert_ne!(*img.get_pixel(W / 2, H / 2), sky);
}

#[test]
fn mesh_behind_camera_leaves_only_sky() {
    let mut r = renderer();
    let sky = sky(&mut r);
    let mesh = r.upload(&encode_geometry(&square(5.0))).expect("upload");
    let draw = at(&mesh, Vec3::new(0.0, 0.0, 6.0), [1.0; 4]);
    let (_, img) = r.render_to_image(&camera(), &[draw]).expect("render");
    assert!(img.pixels().all(|p| *p == sky));
}

#[test]
fn nearer_colour_wins_regardless_of_draw_order() {
    let mut r = renderer();
    let mesh = r.upload(&encode_geometry(&square(0.5))).expect("upload");
    let (near, far) = (Vec3::new(0.0, 0.0, 0.5), Vec3::ZERO);
    for (near_color, far_color) in [(RED, GREEN), (GREEN, RED)] {
        let a = at(&mesh, near, near_color);
        let b = at(&mesh, far, far_color);
        for draws in [[a, b], [b, a]] {
            let (_, img) = r.render_to_image(&camera(), &draws).expect("render");
            let p = img.get_pixel(W / 2, H / 2).0;
            let red_wins = u16::from(p[0]) > 2 * u16::from(p[1]);
            assert_eq!(red_wins, near_color == RED, "pixel {p:?}");
        }
    }
}

#[test]
fn each_draw_gets_its_own_transform_and_colour() {
    let mut r = renderer();
    let mesh = r.upload(&encode_geometry(&square(0.25))).expect("upload");
    // More draws than the initial instance capacity, most of them behind the camera.
    let mut draws = vec![at(&mesh, Vec3::new(0.0, 0.0, 10.0), [1.0; 4]); 97];
    let spots = [(-0.8, RED, 0), (0.0, GREEN, 1), (0.8, BLUE, 2)];
    draws.extend(spots.map(|(x, c, _)| at(&mesh, Vec3::new(x, 0.0, 0.0), c)));
    let (t, img) = r.render_to_image(&camera(), &draws).expect("render");
    assert_eq!(t.draws, 100);
    for (x, _, channel) in spots {
        let (px, py) = pixel_of(Vec3::new(x, 0.0, 0.0));
        let p = img.get_pixel(px, py).0;
        let max = (0..3).max_by_key(|&i| p[i]).unwrap_or(3);
        assert_eq!(max, channel, "pixel {p:?} at {px},{py}");
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let mut r = renderer();
    assert!(matches!(r.read_pixels(), Err(RenderError::NoFrame)));
    let good = encode_geometry(&square(1.0));
    let mut bad_index = good.clone();
    let last = bad_index.len() - 2;
    bad_index[last..].copy_from_slice(&[0xff, 0xff]);
    let noise: Vec<u8> = (0..200u32).map(|i| (i * 37 % 251) as u8).collect();
    for bytes in [&[][..], &noise, &good[..good.len() - 4], &bad_index] {
        assert!(matches!(r.upload(bytes), Err(RenderError::Geometry(_))));
    }
    assert!(matches!(r.resize(0, 10), Err(RenderError::BadSize(0, 10))));
}

/// A segment with u32 indices even though u16 would do (the encoder only widens when needed).
fn wide_segment(mesh: &Mesh) -> Vec<u8> {
    let vertex_offset = std::mem::size_of::<GeometryHeader>();
    let header = GeometryHeader {
        magic: GEOMETRY_MAGIC,
        version: GEOMETRY_VERSION,
        flags: GEOMETRY_U32_INDICES,
        vertex_count: mesh.vertices.len() as u32,
        index_count: mesh.indices.len() as u32,
        vertex_offset: vertex_offset as u32,
        index_offset: (vertex_offset + mesh.vertices.len() * 20) as u32,
        reserved: [0; 2],
    };
    let mut out = bytemuck::bytes_of(&header).to_vec();
    out.extend_from_slice(bytemuck::cast_slice(&mesh.vertices));
    out.extend_from_slice(bytemuck::cast_slice(&mesh.indices));
    out
}

#[test]
fn wide_index_and_empty_meshes_render() {
    let mut r = renderer();
    let sky = sky(&mut r);
    let wide = r.upload(&wide_segment(&square(0.5))).expect("wide upload");
    assert!(wide.wide_indices());
    let empty = r.upload(&encode_geometry(&Mesh::default())).expect("empty");
    assert_eq!(empty.triangles(), 0);
    let draws = [at(&empty, Vec3::ZERO, RED), at(&wide, Vec3::ZERO, GREEN)];
    let (t, img) = r.render_to_image(&camera(), &draws).expect("render");
    assert_eq!((t.draws, t.triangles), (1, 2));
    let p = img.get_pixel(W / 2, H / 2).0;
    assert!(p[1] > p[0] && p[1] > p[2], "{p:?}");
    assert_eq!(*img.get_pixel(0, 0), sky);
}

#[test]
fn calibration_samples_report_work_and_time() {
    let mut r = renderer();
    let sky = sky(&mut r);
    let mesh = r.upload(&encode_geometry(&square(3.0))).expect("upload");
    let costs = r.sample_costs(&mesh, &[1, 8]).expect("costs");
    let work: Vec<(u64, u64)> = costs.iter().map(|c| (c.0, c.1)).collect();
    assert_eq!(work, [(2, 4), (16, 32)]);
    assert!(costs.iter().all(|c| c.2 > 0.0));
    let fill = r.sample_fill(&[0.25, 1.0]).expect("fill");
    let screen = f64::from(W * H) * FILL_LAYERS as f64;
    assert_eq!(fill.len(), 2);
    assert_eq!(
        fill.iter().map(|f| f.0).collect::<Vec<_>>(),
        [0.25 * screen, screen]
    );
    let img = r.read_pixels().expect("last fill frame");
    assert!(
        img.pixels().all(|p| *p != sky),
        "full coverage leaves no sky"
    );
    // The textured samples really sample the checker: dark and light texels on screen.
    let textured = r.sample_textured_fill(&[0.25, 1.0]).expect("textured fill");
    assert_eq!(
        textured.iter().map(|f| f.0).collect::<Vec<_>>(),
        [0.25 * screen, screen]
    );
    let img = r.read_pixels().expect("last textured frame");
    let dark = img.pixels().filter(|p| p[0] < 60).count();
    let light = img.pixels().filter(|p| p[0] > 160).count();
    let n = (W * H) as usize;
    assert!(
        dark > n / 5 && light > n / 5,
        "dark {dark}, light {light} of {n}"
    );
}

/// A box from `min` to `max` with outward normals, as the generator's `add_box` makes it.
fn cuboid(mesh: &mut Mesh, min: Vec3, max: Vec3, color: [f32; 4]) {
    for axis in 0..3 {
        for side in [-1.0f32, 1.0] {
            let mut n = [0.0; 3];
            n[axis] = side;
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = mesh.vertices.len() as u32;
            for (a, b) in [(0, 0), (1, 0), (1, 1), (0, 1)] {
                let mut p = if side < 0.0 { min } else { max };
                p[u] = if a == 0 { min[u] } else { max[u] };
                p[v] = if b == 0 { min[v] } else { max[v] };
                mesh.vertices.push(Vertex::new(p.into(), n, color));
            }
            mesh.indices.extend([0, 1, 2, 0, 2, 3].map(|i| base + i));
        }
    }
}

/// The demo's door leaf seen from 3 m, a little from above (the generator's `door`: a 4.5 cm
/// leaf with two panels raised 6 mm), at `samples` per pixel: how much brighter (R+G+B) than the
/// door just above and below it the brightest pixel is, and where. `picture`: drawn as a
/// picture ([`Renderer::picture_with_boxes`]) rather than as a timed frame.
fn door_seam(samples: u32, picture: bool) -> (i32, u32, u32) {
    let (w, h) = (320, 240);
    let mut r = Renderer::with_samples(w, h, Some(samples)).expect("renderer");
    assert_eq!(r.samples(), samples);
    let wood = [0.45, 0.36, 0.27, 1.0];
    let (t, dw, dh) = (0.045, 0.92, 2.05);
    let mut door = Mesh {
        vertices: vec![],
        indices: vec![],
        uvs: Vec::new(),
    };
    cuboid(
        &mut door,
        Vec3::new(-dw / 2.0, 0.0, -t / 2.0),
        Vec3::new(dw / 2.0, dh, t / 2.0),
        wood,
    );
    for (y0, y1) in [(0.2, 0.95), (1.1, 1.9)] {
        let a = Vec3::new(-dw / 2.0 + 0.12, y0, t / 2.0);
        let b = Vec3::new(dw / 2.0 - 0.12, y1, t / 2.0 + 0.006);
        cuboid(&mut door, a, b, wood);
    }
    let mesh = r.upload(&encode_geometry(&door)).expect("upload");
    let camera = Camera {
        eye: Vec3::new(-1.2, 1.6, 2.8),
        target: Vec3::new(0.0, 1.0, 0.0),
        up: Vec3::Y,
        fovy: 45f32.to_radians(),
        near: 0.1,
        far: 100.0,
    };
    let draws = [at(&mesh, Vec3::ZERO, [1.0; 4])];
    let img = if picture {
        r.picture_with_boxes(&camera, &draws, &[]).expect("picture")
    } else {
        r.render_to_image(&camera, &draws).expect("render").1
    };
    assert_eq!(img.dimensions(), (w, h));
    let sky = self::sky(&mut r).0;
    let luma = |x: u32, y: u32| {
        let p = img.get_pixel(x, y).0;
        (p != sky).then(|| i32::from(p[0]) + i32::from(p[1]) + i32::from(p[2]))
    };
    let mut worst = (0, 0, 0);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let (Some(c), Some(up), Some(down)) = (luma(x, y), luma(x, y - 1), luma(x, y + 1))
            else {
                continue;
            };
            let excess = (c - up).min(c - down);
            if excess > worst.0 {
                worst = (excess, x, y);
            }
        }
    }
    worst
}

/// The panels' top faces are a fraction of a pixel high: sampled once per pixel they light some
/// pixels fully and miss the rest, a dashed white seam across the door (the demo's frames on
/// llvmpipe); with [`SAMPLES`] per pixel every pixel is shaded by its coverage. Measured on
/// llvmpipe: 59 (R+G+B) with one sample, 16 with four. Pictures (saved frames, contact sheets)
/// are drawn at four samples per pixel even on a CPU rasteriser.
#[test]
fn a_door_close_up_has_no_dashed_seams() {
    for (samples, picture) in [(SAMPLES, false), (1, true)] {
        let (excess, x, y) = door_seam(samples, picture);
        assert!(
            excess < 35,
            "{samples} samples{}: a seam pixel at {x},{y} is {excess} brighter (R+G+B) than \
             the door above and below it",
            if picture { ", as a picture" } else { "" }
        );
    }
    let (aliased, ..) = door_seam(1, false);
    assert!(
        aliased >= 35,
        "one sample per pixel should show the dashed seam this test guards against ({aliased})"
    );
}
