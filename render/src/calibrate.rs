//! Timed sample draws for the cost model (Funkhouser §4.2.3): `C1·polys + C2·verts` from frames
//! of many small draws squeezed into a patch, `C3·pixels` from overlapping screen-aligned quads,
//! `C4·pixels` from the same quads textured; [`calibrate`] fits them at start-up, for the walk
//! and the benchmark alike.

use crate::{
    Draw, FILL_LAYERS, FrameTiming, GpuMesh, GpuTexture, RenderError, Renderer, SAMPLE_REPEATS,
};
use glam::{Mat4, Vec3};
use portico_client::cost::CostModel;
use portico_data::geometry::{Aabb, Mesh, Vertex, encode_geometry};

impl Renderer {
    /// Times frames of `n` separate draws of `mesh` for each `n` in `counts`, all squeezed into a
    /// small patch of the screen so that pixel fill stays negligible. Returns
    /// `(triangles, vertices, seconds)` per count, for fitting `C1·polys + C2·verts` (§4.2.3).
    pub fn sample_costs(
        &mut self,
        mesh: &GpuMesh,
        counts: &[u32],
    ) -> Result<Vec<(u64, u64, f64)>, RenderError> {
        let view_proj = fit_to_patch(&mesh.bounds(), 0.1);
        let draw = Draw::new(mesh, Mat4::IDENTITY, [1.0; 4]);
        self.render_view_proj(view_proj, &[draw])?; // warm-up: first use compiles state
        counts
            .iter()
            .map(|&n| {
                let draws = vec![draw; n as usize];
                let t = self.fastest_frame(view_proj, &draws)?;
                Ok((t.triangles, t.vertices, t.total_s))
            })
            .collect()
    }

    /// Times frames of four (`FILL_LAYERS`) overlapping screen-aligned quads, each covering the given
    /// fraction of the screen. Returns `(pixels written, seconds)` per coverage, for fitting
    /// `C3·pixels` (§4.2.3).
    pub fn sample_fill(&mut self, coverage: &[f32]) -> Result<Vec<(f64, f64)>, RenderError> {
        self.sample_fill_with(coverage, None)
    }

    /// [`Renderer::sample_fill`] with the quads textured by a 256 × 256 mip-mapped checker
    /// repeated twice across each (about a texel per pixel at 640 × 480): for fitting
    /// `(C3 + C4)·pixels`.
    pub fn sample_textured_fill(
        &mut self,
        coverage: &[f32],
    ) -> Result<Vec<(f64, f64)>, RenderError> {
        let texture = checker_texture(self)?;
        self.sample_fill_with(coverage, Some(&texture))
    }

    fn sample_fill_with(
        &mut self,
        coverage: &[f32],
        texture: Option<&GpuTexture>,
    ) -> Result<Vec<(f64, f64)>, RenderError> {
        let mut mesh = unit_quad();
        if texture.is_some() {
            mesh.uvs = vec![[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
        }
        let quad = self.upload(&portico_data::geometry::encode_geometry(&mesh))?;
        let screen = f64::from(self.width) * f64::from(self.height);
        let warm: Vec<Draw<'_>> = fill_layers(&quad, 0.01)
            .into_iter()
            .map(|d| Draw { texture, ..d })
            .collect();
        self.render_view_proj(Mat4::IDENTITY, &warm)?; // warm-up: first use compiles state
        coverage
            .iter()
            .map(|&c| {
                let c = c.clamp(0.0, 1.0);
                let draws: Vec<Draw<'_>> = fill_layers(&quad, c)
                    .into_iter()
                    .map(|d| Draw { texture, ..d })
                    .collect();
                let t = self.fastest_frame(Mat4::IDENTITY, &draws)?;
                Ok((
                    (f64::from(c) * screen).round() * FILL_LAYERS as f64,
                    t.total_s,
                ))
            })
            .collect()
    }

    /// The fastest of [`SAMPLE_REPEATS`] frames of the same draws.
    fn fastest_frame(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
    ) -> Result<FrameTiming, RenderError> {
        let mut best = self.render_view_proj(view_proj, draws)?;
        for _ in 1..SAMPLE_REPEATS {
            let t = self.render_view_proj(view_proj, draws)?;
            if t.total_s < best.total_s {
                best = t;
            }
        }
        Ok(best)
    }
}

/// A clip-space matrix that maps `bounds` into a centred square patch of half-size `half`
/// (in NDC units) at depths within 0.1..0.9.
pub(crate) fn fit_to_patch(bounds: &Aabb, half: f32) -> Mat4 {
    let radius = if bounds.is_empty() {
        1.0
    } else {
        (bounds.size().max_element() * 0.5).max(1e-6)
    };
    Mat4::from_translation(Vec3::new(0.0, 0.0, 0.5))
        * Mat4::from_scale(Vec3::new(half, half, 0.4) / radius)
        * Mat4::from_translation(-bounds.center())
}

/// A 256 × 256 black-and-white checker of 32-texel squares with its full mip chain, repeating.
fn checker_texture(r: &Renderer) -> Result<GpuTexture, RenderError> {
    use portico_data::texture::{Wrap, cut_segments, mip_chain};
    let side = 256u32;
    let rgba: Vec<u8> = (0..side * side)
        .flat_map(|i| {
            let (x, y) = (i % side, i / side);
            let v = if (x / 32 + y / 32) % 2 == 0 { 230 } else { 25 };
            [v, v, v, 255]
        })
        .collect();
    let chain = mip_chain(side, side, &rgba);
    let finest = cut_segments(side, side, &chain)
        .pop()
        .map(|s| s.3)
        .unwrap_or_default();
    r.upload_texture(&finest, [Wrap::Repeat; 2])
}

/// A quad covering NDC `[-1, 1]²` at z = 0, facing +z, white.
pub(crate) fn unit_quad() -> portico_data::geometry::Mesh {
    let corner = |x: f32, y: f32| Vertex::new([x, y, 0.0], [0.0, 0.0, 1.0], [1.0; 4]);
    portico_data::geometry::Mesh {
        vertices: vec![
            corner(-1.0, -1.0),
            corner(1.0, -1.0),
            corner(1.0, 1.0),
            corner(-1.0, 1.0),
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
        uvs: Vec::new(),
    }
}

/// [`FILL_LAYERS`] centred quads each covering `coverage` of the screen, drawn far to near.
pub(crate) fn fill_layers(quad: &GpuMesh, coverage: f32) -> Vec<Draw<'_>> {
    let s = coverage.sqrt();
    (0..FILL_LAYERS)
        .map(|k| {
            let z = 0.9 - 0.8 * k as f32 / FILL_LAYERS as f32;
            Draw::new(
                quad,
                Mat4::from_translation(Vec3::new(0.0, 0.0, z))
                    * Mat4::from_scale(Vec3::new(s, s, 1.0)),
                [1.0; 4],
            )
        })
        .collect()
}

/// Funkhouser §4.2.3: C1, C2, C3 and our C4 from timed sample draws at start-up (the walk and
/// the benchmark both start this way): a 24 × 24 grid patch drawn 1 to 128 times, and
/// full-screen quads at three coverages, plain and textured.
pub fn calibrate(r: &mut Renderer) -> Result<CostModel, RenderError> {
    let n = 24u32;
    let mut mesh = Mesh::default();
    for j in 0..=n {
        for i in 0..=n {
            let p = [i as f32 / n as f32, j as f32 / n as f32, 0.0];
            mesh.vertices
                .push(Vertex::new(p, [0.0, 0.0, 1.0], [0.8, 0.8, 0.8, 1.0]));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            mesh.indices
                .extend([a, a + 1, a + n + 1, a + 1, a + n + 2, a + n + 1]);
        }
    }
    let gpu = r.upload(&encode_geometry(&mesh))?;
    let geometry = r.sample_costs(&gpu, &[1, 16, 64, 128])?;
    // Plain and textured fill back to back at each coverage, so that a machine's drift
    // between them does not pass for the texture's cost.
    let (mut fill, mut textured) = (Vec::new(), Vec::new());
    for c in [0.25, 0.5, 1.0] {
        fill.extend(r.sample_fill(&[c])?);
        textured.extend(r.sample_textured_fill(&[c])?);
    }
    Ok(CostModel::calibrate(&geometry, &fill, &textured))
}
