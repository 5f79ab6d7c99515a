//! Materials on the test machine's adapter (llvmpipe in CI): assimp's BoxTextured sample drawn
//! with its texture, a cut-out material's transparent texels dropped, a blended one mixed over
//! what is behind it.

use glam::{Mat4, Vec3, Vec4};
use portico_data::geometry::{Mesh, Vertex, encode_geometry};
use portico_data::import::import_file;
use portico_data::texture::{TextureImage, Wrap, cut_segments, mip_chain, to_linear, to_srgb};
use portico_render::{AlphaMode, Camera, Draw, GpuTexture, Renderer};

const W: u32 = 160;
const H: u32 = 120;

fn renderer() -> Renderer {
    let mut r = Renderer::with_samples(W, H, Some(1))
        .unwrap_or_else(|e| panic!("no wgpu adapter/device (CI has llvmpipe): {e}"));
    // Full ambient: every surface shows its colour unshaded.
    r.set_light(Vec3::Z, 1.0);
    r
}

fn camera(eye: Vec3) -> Camera {
    Camera {
        eye,
        target: Vec3::ZERO,
        up: Vec3::Y,
        fovy: 60f32.to_radians(),
        near: 0.1,
        far: 100.0,
    }
}

/// Uploads the finest segment of an image's mip chain.
fn upload(r: &Renderer, t: &TextureImage) -> GpuTexture {
    let chain = mip_chain(t.width, t.height, &t.rgba);
    let segs = cut_segments(t.width, t.height, &chain);
    r.upload_texture(&segs.last().unwrap().3, t.wrap).unwrap()
}

/// Mean colour (sRGB bytes, averaged in linear light) and the spread of luminance (bytes) of
/// the pixels `at` gives.
fn mean(pixels: impl Iterator<Item = [u8; 4]>) -> ([u8; 3], f32) {
    let (mut sum, mut lum, mut lum2, mut n) = ([0.0f64; 3], 0.0f64, 0.0f64, 0.0f64);
    for p in pixels {
        for c in 0..3 {
            sum[c] += to_linear(p[c]) as f64;
        }
        let l = (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0;
        lum += l;
        lum2 += l * l;
        n += 1.0;
    }
    let spread = (lum2 / n - (lum / n).powi(2)).max(0.0).sqrt() as f32;
    (sum.map(|s| to_srgb((s / n) as f32)), spread)
}

/// Where a texture coordinate lands in `0..1` under a wrap mode.
fn wrap(x: f32, w: Wrap) -> f32 {
    match w {
        Wrap::Repeat => x.rem_euclid(1.0),
        Wrap::Mirror => {
            let t = x.rem_euclid(2.0);
            if t > 1.0 { 2.0 - t } else { t }
        }
        Wrap::Clamp => x.clamp(0.0, 0.999_999),
    }
}

#[test]
fn box_textured_shows_its_texture_on_each_face() {
    // The .gltf's sampler mirrors along u and clamps along v; the other two repeat.
    for file in [
        "BoxTextured-glTF/BoxTextured.gltf",
        "BoxTextured-glTF-Binary/BoxTextured.glb",
        "BoxTextured-glTF-Embedded/BoxTextured.gltf",
    ] {
        box_textured(file);
    }
}

fn box_textured(file: &str) {
    let m = import_file(&std::path::Path::new("/usr/share/assimp/models/glTF2").join(file))
        .expect("BoxTextured (install assimp-testmodels)");
    let tex = &m.textures[0];
    let mesh = m.defs[0].lods[0].transformed(&m.instances[0].transform);
    let mut r = renderer();
    let gpu = r.upload(&encode_geometry(&mesh)).unwrap();
    let texture = upload(&r, tex);
    for (axis, eye) in [(2, Vec3::new(0.0, 0.0, 2.5)), (0, Vec3::new(2.5, 0.0, 0.0))] {
        // The face looking at the camera: its corners and their coordinates.
        let face: Vec<(Vec3, [f32; 2])> = mesh
            .vertices
            .iter()
            .zip(&mesh.uvs)
            .filter(|(v, _)| v.normal_f32()[axis] > 0.9)
            .map(|(v, uv)| (Vec3::from(v.position), *uv))
            .collect();
        assert_eq!(face.len(), 4, "axis {axis}");
        let cam = camera(eye);
        let mut draw = Draw::new(&gpu, Mat4::IDENTITY, [1.0; 4]);
        draw.texture = Some(&texture);
        r.render(&cam, &[draw]).unwrap();
        let img = r.read_pixels().unwrap();
        // The middle 60 % of the face on screen against the middle 60 % of its texture.
        let vp = cam.view_proj(W as f32 / H as f32);
        let px: Vec<(f32, f32)> = face
            .iter()
            .map(|(p, _)| {
                let c = vp * Vec4::new(p.x, p.y, p.z, 1.0);
                let (x, y) = (c.x / c.w, c.y / c.w);
                ((x + 1.0) * 0.5 * W as f32, (1.0 - y) * 0.5 * H as f32)
            })
            .collect();
        let span = |v: Vec<f32>| {
            let (lo, hi) = v
                .iter()
                .fold((f32::MAX, f32::MIN), |a, &x| (a.0.min(x), a.1.max(x)));
            (lo + 0.2 * (hi - lo), hi - 0.2 * (hi - lo))
        };
        let (x0, x1) = span(px.iter().map(|p| p.0).collect());
        let (y0, y1) = span(px.iter().map(|p| p.1).collect());
        let drawn = mean(
            img.enumerate_pixels()
                .filter(|(x, y, _)| {
                    (x0..x1).contains(&(*x as f32 + 0.5)) && (y0..y1).contains(&(*y as f32 + 0.5))
                })
                .map(|(_, _, p)| p.0),
        );
        let (u0, u1) = span(face.iter().map(|f| f.1[0]).collect());
        let (v0, v1) = span(face.iter().map(|f| f.1[1]).collect());
        let n = 96;
        let want = mean((0..n * n).map(|i| {
            let u = u0 + (u1 - u0) * ((i % n) as f32 + 0.5) / n as f32;
            let v = v0 + (v1 - v0) * ((i / n) as f32 + 0.5) / n as f32;
            let tx = (wrap(u, tex.wrap[0]) * tex.width as f32) as u32 % tex.width;
            let ty = (wrap(v, tex.wrap[1]) * tex.height as f32) as u32 % tex.height;
            let o = ((ty * tex.width + tx) * 4) as usize;
            [tex.rgba[o], tex.rgba[o + 1], tex.rgba[o + 2], 255]
        }));
        for c in 0..3 {
            let d = drawn.0[c].abs_diff(want.0[c]);
            assert!(
                d <= 8,
                "{file} axis {axis}: drawn {:?}, texture {:?}",
                drawn.0,
                want.0
            );
        }
        // Its texture, not one colour: the logo's contrast survives.
        assert!(
            drawn.1 > 0.5 * want.1 && want.1 > 20.0,
            "{file} axis {axis}: spread drawn {} texture {}",
            drawn.1,
            want.1
        );
    }
}

/// A unit quad in the plane z = 0 facing +z, u across x, v down y, in `color`.
fn quad(color: [f32; 4], z: f32) -> Mesh {
    let v = |x: f32, y: f32| Vertex::new([x, y, z], [0.0, 0.0, 1.0], color);
    Mesh {
        vertices: vec![v(-1.0, -1.0), v(1.0, -1.0), v(1.0, 1.0), v(-1.0, 1.0)],
        indices: vec![0, 1, 2, 0, 2, 3],
        uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
    }
}

#[test]
fn cut_outs_drop_transparent_texels_and_blends_mix() {
    let mut r = renderer();
    r.set_clear(portico_render::wgpu::Color::BLACK);
    // Left half transparent red, right half opaque green.
    let img = TextureImage {
        name: "half".into(),
        width: 4,
        height: 1,
        rgba: [
            [255, 0, 0, 0],
            [255, 0, 0, 0],
            [0, 255, 0, 255],
            [0, 255, 0, 255],
        ]
        .concat(),
        wrap: [Wrap::Clamp; 2],
    };
    let texture = upload(&r, &img);
    let front = r.upload(&encode_geometry(&quad([1.0; 4], 0.0))).unwrap();
    let cam = camera(Vec3::new(0.0, 0.0, 1.5));
    let at = |img: &image::RgbaImage, fx: f32| img.get_pixel((fx * W as f32) as u32, H / 2).0;
    let mut draw = Draw::new(&front, Mat4::IDENTITY, [1.0; 4]);
    draw.texture = Some(&texture);
    draw.alpha = AlphaMode::Mask(0.5);
    r.render(&cam, &[draw]).unwrap();
    let masked = r.read_pixels().unwrap();
    assert_eq!(
        &at(&masked, 0.3)[..3],
        &[0, 0, 0],
        "a cut-out texel is not drawn"
    );
    assert_eq!(&at(&masked, 0.7)[..3], &[0, 255, 0]);
    draw.alpha = AlphaMode::Opaque;
    r.render(&cam, &[draw]).unwrap();
    let opaque = r.read_pixels().unwrap();
    assert_eq!(&at(&opaque, 0.3)[..3], &[255, 0, 0], "opaque ignores alpha");

    // Half-transparent red over opaque blue, listed first: still drawn after the blue.
    let back = r
        .upload(&encode_geometry(&quad([0.0, 0.0, 1.0, 1.0], -0.5)))
        .unwrap();
    let mut glass = Draw::new(&front, Mat4::IDENTITY, [1.0, 0.0, 0.0, 0.5]);
    glass.alpha = AlphaMode::Blend;
    let wall = Draw::new(&back, Mat4::IDENTITY, [1.0; 4]);
    r.render(&cam, &[glass, wall]).unwrap();
    let mixed = at(&r.read_pixels().unwrap(), 0.5);
    // Half and half in linear light: 0.5 each, sRGB 188.
    for (got, want) in mixed[..3].iter().zip([188u8, 0, 188]) {
        assert!(got.abs_diff(want) <= 3, "{mixed:?}");
    }
}

/// A texture a client holds, in each texel format the adapter offers (llvmpipe offers BC and
/// ETC2): its GPU bytes are what its segment record says it costs the cache, at most a byte per
/// texel of its finest level plus the coarser levels' third when block-compressed; drawn, each
/// quadrant shows its own colour and a photograph-like picture the RGBA8 one's (so the blocks
/// are in the order and format the GPU reads), opaque (BC1, ETC2) and with alpha (BC3; RGBA8
/// on an ETC2 GPU) alike.
#[test]
fn textures_are_held_block_compressed_where_the_adapter_takes_them() {
    use portico_data::texture::{MipSegment, TexelFormat, full_levels};
    let mut r = renderer();
    let llvmpipe = r.adapter_info().to_ascii_lowercase().contains("llvmpipe");
    let rgba8 = std::env::var("PORTICO_TEXELS").is_ok_and(|v| v.eq_ignore_ascii_case("rgba8"));
    if llvmpipe && !rgba8 {
        assert_eq!(r.texel_format(), TexelFormat::Block, "llvmpipe offers BC");
    }
    // Top left, top right, bottom left, bottom right.
    let colours = [
        [200u8, 40, 40],
        [40, 200, 40],
        [40, 40, 200],
        [220, 220, 60],
    ];
    let (w, h) = (64, 64);
    let quad_mesh = r.upload(&encode_geometry(&quad([1.0; 4], 0.0))).unwrap();
    let cam = camera(Vec3::new(0.0, 0.0, 1.5));
    let vp = cam.view_proj(W as f32 / H as f32);
    let image = |alpha: u8, smooth: bool| TextureImage {
        name: "quadrants".into(),
        width: w,
        height: h,
        rgba: (0..w * h)
            .flat_map(|i| {
                let (x, y) = (i % w, i / w);
                let c = if smooth {
                    let (fx, fy) = (x as f32, y as f32);
                    [
                        (128.0 + 100.0 * (fx / 7.0).sin()) as u8,
                        (128.0 + 90.0 * (fy / 5.0).cos()) as u8,
                        (100.0 + 80.0 * ((fx + fy) / 11.0).sin()) as u8,
                    ]
                } else {
                    colours[((y / 32) * 2 + x / 32) as usize]
                };
                [c[0], c[1], c[2], alpha]
            })
            .collect(),
        wrap: [Wrap::Clamp; 2],
    };
    let draw_it = |r: &mut Renderer, img: &TextureImage| {
        let gpu = upload(r, img);
        let mut draw = Draw::new(&quad_mesh, Mat4::IDENTITY, [1.0; 4]);
        draw.texture = Some(&gpu);
        r.render(&cam, &[draw]).unwrap();
        (gpu.gpu_bytes(), r.read_pixels().unwrap())
    };
    r.set_texel_format(TexelFormat::Rgba8);
    let (_, plain_smooth) = draw_it(&mut r, &image(255, true));
    for texels in [TexelFormat::Rgba8, TexelFormat::Block, TexelFormat::Etc2] {
        if !r.set_texel_format(texels) {
            assert!(!llvmpipe, "llvmpipe offers {texels:?}");
            continue;
        }
        for alpha in [255u8, 200] {
            let (bytes, shot) = draw_it(&mut r, &image(alpha, false));
            let record = MipSegment {
                segment: 0,
                width: w,
                height: h,
                levels: full_levels(w, h),
                opaque: alpha == 255,
                parts: 0,
            };
            assert_eq!(bytes, record.gpu_bytes(texels), "{texels:?}");
            let per_texel = match (texels, alpha) {
                (TexelFormat::Rgba8, _) | (TexelFormat::Etc2, 200) => 4.0,
                (_, 255) => 0.5,
                _ => 1.0,
            };
            let most = (w * h) as f64 * per_texel * 4.0 / 3.0 + 64.0;
            assert!(bytes as f64 <= most, "{texels:?}: {bytes} bytes");
            // The quad's u runs along x, v down y: the texture's top left is the quad's.
            for (q, at) in [(-0.5f32, 0.5f32), (0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)]
                .iter()
                .enumerate()
            {
                let c = vp * Vec4::new(at.0, at.1, 0.0, 1.0);
                let (x, y) = (c.x / c.w, c.y / c.w);
                let (px, py) = ((x + 1.0) * 0.5 * W as f32, (1.0 - y) * 0.5 * H as f32);
                let got = shot.get_pixel(px as u32, py as u32).0;
                for k in 0..3 {
                    assert!(
                        got[k].abs_diff(colours[q][k]) <= 6,
                        "{texels:?}, alpha {alpha}, quadrant {q}: drew {got:?}, texture {:?}",
                        colours[q]
                    );
                }
            }
        }
        // A picture, not flat colours: within what the format loses of the RGBA8 frame.
        let (_, smooth) = draw_it(&mut r, &image(255, true));
        let p = portico_data::texture::psnr(plain_smooth.as_raw(), smooth.as_raw());
        eprintln!("{texels:?}: the picture drawn at {p:.1} dB against RGBA8");
        assert!(p >= 30.0, "{texels:?}: {p:.1} dB against RGBA8");
    }
}
