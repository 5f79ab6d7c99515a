//! The visibility stage of one frame (Funkhouser §4.1.2) and the candidates it hands to detail
//! elision: eye-to-cell and eye-to-object culling through the portals of the server's cell
//! graph with the eye cell's stab list (or, while that stab list is not yet resident, every
//! object in the reached cells' wedges), then each visible object's screen size and focus.

use crate::elision::{Candidate, LodOption};
use glam::{Mat4, Vec3, Vec4};
use portico_data::cells::realtime::{
    Frustum, eye_to_cell, eye_to_object, eye_to_object_unlisted, frustum_to_object,
};
use portico_data::cells::{CellGraph, StabList};
use portico_data::format::Header;
use portico_data::geometry::Aabb;

/// What the visibility stage found.
#[derive(Debug, Clone, Default)]
pub struct Visible {
    /// Cells visible from the eye.
    pub cells: u32,
    /// Visible instances, sorted.
    pub objects: Vec<u32>,
    /// The eye cell's stab list was not resident: the looser culling without it was used
    /// (reached cells' wedges, or the plain frustum outside every live cell).
    pub fallback: bool,
    /// The eye's cell, if inside a live cell.
    pub eye_cell: Option<u32>,
}

/// Eye-to-object visibility with whatever the cache holds.
pub fn visible(
    graph: Option<&CellGraph>,
    stab: &dyn Fn(u32) -> Option<std::sync::Arc<StabList>>,
    bounds: &[Aabb],
    view: &Frustum,
) -> Visible {
    let Some(graph) = graph else {
        return Visible {
            cells: 0,
            objects: frustum_to_object(bounds, view),
            fallback: true,
            eye_cell: None,
        };
    };
    let eye_cell = graph
        .locate(view.eye)
        .filter(|&c| graph.cells[c as usize].live);
    let reached = eye_to_cell(graph, view);
    match eye_cell.and_then(stab) {
        Some(list) => Visible {
            cells: reached.len() as u32,
            objects: eye_to_object(&reached, &list, bounds),
            fallback: false,
            eye_cell,
        },
        // The stab list is on its way: the cells reached through the portals bound what can be
        // seen (outside every live cell nothing does, and only the frustum is left).
        None if eye_cell.is_some() => Visible {
            cells: reached.len() as u32,
            objects: eye_to_object_unlisted(graph, &reached, bounds),
            fallback: true,
            eye_cell,
        },
        None => Visible {
            cells: 0,
            objects: frustum_to_object(bounds, view),
            fallback: true,
            eye_cell,
        },
    }
}

/// Screen area in pixels of a box's projection (its screen-space bounding rectangle, clipped to
/// the screen); the whole screen when the box reaches behind the near plane.
pub fn screen_pixels(b: &Aabb, view_proj: &Mat4, width: u32, height: u32) -> f32 {
    let (mut lo, mut hi) = (glam::Vec2::splat(f32::MAX), glam::Vec2::splat(f32::MIN));
    for i in 0..8 {
        let c = Vec3::new(
            if i & 1 == 0 { b.min[0] } else { b.max[0] },
            if i & 2 == 0 { b.min[1] } else { b.max[1] },
            if i & 4 == 0 { b.min[2] } else { b.max[2] },
        );
        let p = *view_proj * Vec4::new(c.x, c.y, c.z, 1.0);
        if p.w <= 1e-4 {
            return (width * height) as f32;
        }
        let ndc = glam::Vec2::new(p.x, p.y) / p.w;
        lo = lo.min(ndc);
        hi = hi.max(ndc);
    }
    let lo = lo.clamp(glam::Vec2::splat(-1.0), glam::Vec2::ONE);
    let hi = hi.clamp(glam::Vec2::splat(-1.0), glam::Vec2::ONE);
    let size = (hi - lo).max(glam::Vec2::ZERO) * 0.5;
    size.x * width as f32 * size.y * height as f32
}

/// Near plane distance of every view (metres): also the margin by which an eye counts as
/// inside a cluster's box.
pub const NEAR: f32 = 0.05;

/// A perspective viewpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position (world).
    pub eye: Vec3,
    /// Point looked at (world).
    pub target: Vec3,
    /// Up direction (world).
    pub up: Vec3,
    /// Vertical field of view in radians, in `(0, π)`.
    pub fovy: f32,
    /// Near plane distance, `> 0`.
    pub near: f32,
    /// Far plane distance, `> near`.
    pub far: f32,
}

impl Camera {
    /// World-to-clip matrix: right-handed view, WebGPU clip space (depth 0..1, y up).
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        let proj =
            glam::camera::rh::proj::directx::perspective(self.fovy, aspect, self.near, self.far);
        proj * glam::camera::rh::view::look_at_mat4(self.eye, self.target, self.up)
    }
}

/// The far plane for a model with these bounds: beyond the whole model from anywhere in it.
pub fn far_plane(bounds: &Aabb) -> f32 {
    bounds.size().length().max(10.0) * 1.5
}

/// Horizontal half field of view (radians) of a view `fovy` high (radians) at this aspect.
pub fn half_fov_x(fovy: f32, aspect: f32) -> f32 {
    ((fovy * 0.5).tan() * aspect).atan()
}

/// How an observer moves: its velocity and how its view direction turns.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Motion {
    /// Metres per second.
    pub velocity: Vec3,
    /// Angular velocity of the view direction: radians per second about the axis it points
    /// along.
    pub turn: Vec3,
}

impl Motion {
    /// The motion that takes an observer at `eye` looking along `dir` to `next_eye` looking
    /// along `next_dir` in `dt` seconds (zero for `dt` ≤ 0 or directions that are not
    /// finite).
    pub fn between(eye: Vec3, dir: Vec3, next_eye: Vec3, next_dir: Vec3, dt: f32) -> Motion {
        if dt <= 0.0 || !dt.is_finite() {
            return Motion::default();
        }
        let velocity = (next_eye - eye) / dt;
        let (a, b) = (dir.normalize_or_zero(), next_dir.normalize_or_zero());
        let axis = a.cross(b);
        let angle = axis.length().atan2(a.dot(b));
        let turn = axis.normalize_or_zero() * (angle / dt);
        Motion {
            velocity: if velocity.is_finite() {
                velocity
            } else {
                Vec3::ZERO
            },
            turn: if turn.is_finite() { turn } else { Vec3::ZERO },
        }
    }
}

/// The observer a client at `eye` looking along `dir` and moving with `motion` announces to the
/// server, with its field of view (`fovy` high at `aspect`) and its speed limits.
pub fn observer(
    eye: Vec3,
    dir: Vec3,
    motion: Motion,
    fovy: f32,
    aspect: f32,
    max_speed: f32,
    max_turn: f32,
) -> portico_protocol::Observer {
    portico_protocol::Observer {
        eye: eye.into(),
        dir: dir.into(),
        up: [0.0, 1.0, 0.0],
        velocity: motion.velocity.into(),
        half_fov_x: half_fov_x(fovy, aspect),
        half_fov_y: fovy * 0.5,
        max_speed,
        max_turn,
        turn: motion.turn.into(),
    }
}

/// Where the frame is seen from: everything the frame decision and the renderer need of the
/// observer, worked out once per frame.
#[derive(Debug, Clone, Copy)]
pub struct Viewpoint {
    /// The camera (eye, target, field of view, near and far planes).
    pub camera: Camera,
    /// World-to-clip matrix.
    pub view_proj: Mat4,
    /// Eye position.
    pub eye: Vec3,
    /// Unit view direction.
    pub dir: Vec3,
    /// Image size in pixels.
    pub size: (u32, u32),
    /// Horizontal half field of view (radians), for the focus term.
    pub half_fov: f32,
    /// Vertical half field of view (radians).
    pub half_fov_y: f32,
}

impl Viewpoint {
    /// The view from `eye` along `dir`, `fovy` high (radians), onto an image of `size`, with
    /// its far plane at `far`.
    pub fn new(eye: Vec3, dir: Vec3, fovy: f32, size: (u32, u32), far: f32) -> Viewpoint {
        let aspect = size.0 as f32 / size.1.max(1) as f32;
        let camera = Camera {
            eye,
            target: eye + dir,
            up: Vec3::Y,
            fovy,
            near: NEAR,
            far,
        };
        Viewpoint {
            view_proj: camera.view_proj(aspect),
            camera,
            eye,
            dir,
            size,
            half_fov: half_fov_x(fovy, aspect),
            half_fov_y: fovy * 0.5,
        }
    }

    /// The view an observer announces, onto an image of `size`, far plane at `far`.
    pub fn of(obs: &portico_protocol::Observer, size: (u32, u32), far: f32) -> Viewpoint {
        Viewpoint::new(
            obs.eye.into(),
            obs.dir.into(),
            obs.half_fov_y * 2.0,
            size,
            far,
        )
    }

    /// The view frustum (side planes only: walls do the far culling).
    pub fn frustum(&self) -> Frustum {
        Frustum::new(self.eye, self.dir, Vec3::Y, self.half_fov, self.half_fov_y)
    }

    /// Whether the eye is inside `b` (within the near-plane margin): no box stands in for
    /// what surrounds the eye.
    pub fn inside(&self, b: &Aabb) -> bool {
        (0..3).all(|i| b.min[i] - NEAR <= self.eye[i] && self.eye[i] <= b.max[i] + NEAR)
    }
}

/// Elision candidates for the visible objects; `resident(segment)` says what the cache holds.
pub fn candidates(
    header: &Header,
    objects: &[u32],
    v: &Viewpoint,
    resident: &dyn Fn(u32) -> bool,
) -> Vec<Candidate> {
    objects
        .iter()
        .filter_map(|&o| {
            let inst = header.instances.get(o as usize)?;
            let texels = resident_texels(header, inst, resident);
            let lods: Vec<LodOption> = header
                .lods_of(inst)
                .iter()
                .map(|l| LodOption {
                    texels: texels.map(|t| if l.uv { t } else { 0.0 }),
                    ..LodOption::new(l.triangles, l.vertices, l.error, resident(l.segment))
                })
                .collect();
            let pixels = screen_pixels(&inst.bounds, &v.view_proj, v.size.0, v.size.1);
            let to = inst.bounds.center() - v.eye;
            let angle = to.try_normalize().map_or(0.0, |t| t.angle_between(v.dir));
            let mut c = Candidate::new(o, lods, pixels);
            c.focus = (1.0 - angle / v.half_fov.max(1e-3)).clamp(0.0, 1.0);
            Some(c)
        })
        .collect()
}

/// A textured instance's texels over the whole object at the finest resident mip level (0 with
/// none resident: it draws in the average colour); `None` for an untextured instance
/// ([`LodOption::texels`]). `uv_span` is the larger axis's repeat count, so a texture repeated
/// along one axis only is overcounted: the accuracy it feeds saturates long before that matters.
fn resident_texels(
    header: &Header,
    inst: &portico_data::format::InstanceRecord,
    resident: &dyn Fn(u32) -> bool,
) -> Option<f32> {
    let t = header.texture_of(inst)?;
    let span = header
        .objects
        .get(inst.object as usize)
        .map_or(1.0, |o| o.uv_span);
    let span = if span.is_finite() && span > 0.0 {
        span
    } else {
        1.0
    };
    let finest = t.segments.iter().rev().find(|s| resident(s.segment));
    Some(finest.map_or(0.0, |s| s.width as f32 * s.height as f32 * span * span))
}

/// Funkhouser ran his prefetch experiments (§5.3) with the optimizing elider "combined with a
/// static detail elision size threshold": no object is drawn finer than the LOD whose average
/// polygon covers `threshold` pixels — the same cap the server's lookahead puts on each object
/// (`portico_data::prefetch::lookahead::max_lod`), so a client never wants a LOD no prefetch
/// would ever send. Drops each candidate's finer LODs (keeping at least the coarsest) and
/// returns, per candidate, how many were dropped (add it to a choice's LOD index).
pub fn cap_detail(cands: &mut [Candidate], threshold: f32) -> Vec<usize> {
    cands
        .iter_mut()
        .map(|c| {
            let last = c.lods.len().saturating_sub(1);
            let keep = c
                .lods
                .iter()
                .position(|l| c.pixels / l.triangles.max(1) as f32 >= threshold)
                .unwrap_or(last);
            c.lods.drain(..keep);
            keep
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearer_boxes_cover_more_pixels_and_behind_covers_the_screen() {
        let cam = Camera {
            eye: Vec3::ZERO,
            target: Vec3::NEG_Z,
            up: Vec3::Y,
            fovy: 1.0,
            near: 0.1,
            far: 100.0,
        };
        let vp = cam.view_proj(4.0 / 3.0);
        let boxed = |z: f32| Aabb {
            min: [-0.5, -0.5, z - 0.5],
            max: [0.5, 0.5, z + 0.5],
        };
        let near = screen_pixels(&boxed(-3.0), &vp, 640, 480);
        let far = screen_pixels(&boxed(-10.0), &vp, 640, 480);
        assert!(near > far * 4.0, "{near} vs {far}");
        assert!(far > 0.0);
        assert_eq!(screen_pixels(&boxed(0.0), &vp, 640, 480), 640.0 * 480.0);
        // Off to the side, clipped away.
        let side = Aabb {
            min: [50.0, -0.5, -3.5],
            max: [51.0, 0.5, -2.5],
        };
        assert_eq!(screen_pixels(&side, &vp, 640, 480), 0.0);
    }

    #[test]
    fn detail_is_capped_at_the_size_threshold() {
        let lod = |triangles| LodOption::new(triangles, triangles, 0.0, true);
        let lods = vec![lod(1000), lod(100), lod(10)];
        let mut cands = vec![
            Candidate::new(0, lods.clone(), 16_000.0), // 16 px per triangle at the finest
            Candidate::new(1, lods.clone(), 1_600.0),  // only the middle one reaches 16
            Candidate::new(2, lods, 16.0),             // none does: keep the coarsest
        ];
        assert_eq!(cap_detail(&mut cands, 16.0), vec![0, 1, 2]);
        let left: Vec<usize> = cands.iter().map(|c| c.lods.len()).collect();
        assert_eq!(left, vec![3, 2, 1]);
        assert_eq!(cands[1].lods[0].triangles, 100);
    }
}
