//! The model hierarchy of clusters (Maciel §6.1, §6.3; Selçuk's far boxes): instances grouped
//! bottom-up by proximity into an octree-like tree whose inner nodes carry cheap stand-ins for
//! everything beneath them, so that far parts of a building cost a few textured quads and the
//! stream can bring the coarse view of a whole wing before its furniture.
//!
//! Building (§6.3.2): a grid over the model, its cells doubling in size each pass; a cell that
//! holds two or more of the current top-level nodes (instances or earlier clusters) COMPLETELY
//! becomes a cluster of them; passes go on until one root is left. Each cluster carries two
//! representations (§5.2): an average-colour box (six face colours, stored in the header, always
//! available) and a textured box (one texture segment: the six orthographic views of the
//! cluster's own objects, captured at build time from the real geometry, never from child
//! impostors). Both cost 12 triangles, so Maciel's rule — a node's costliest representation
//! costs less than the sum of its children's cheapest — holds for every node with two or more
//! children, which is every node ([`Hierarchy::check`]).

use crate::geometry::{Aabb, Mesh};
use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

/// Triangles of a box stand-in (average-colour or textured).
pub const BOX_TRIANGLES: u32 = 12;
/// Vertices of a box stand-in (four per face, so faces can have their own colour or texture).
pub const BOX_VERTICES: u32 = 24;

/// The six faces of a box, in the order of [`ClusterNode::face_colors`] and of the texture
/// atlas tiles: −x, +x, −y, +y, −z, +z.
pub const FACES: [(usize, f32); 6] = [
    (0, -1.0),
    (0, 1.0),
    (1, -1.0),
    (1, 1.0),
    (2, -1.0),
    (2, 1.0),
];

/// Texels per metre of a cluster's face views (a 7 m room gets 42-pixel tiles: impostors stand
/// in for clusters that are small on the screen).
pub const TEXELS_PER_METRE: f32 = 6.0;
/// Smallest and largest atlas tile side.
pub const TILE_RANGE: (u32, u32) = (8, 64);
/// Clusters smaller than this (largest side, metres) get no textured box: at the distances
/// where they would be drawn as one, the average-colour box looks the same.
pub const MIN_TEXTURED_SIZE: f32 = 1.5;
/// Grid cell of the first clustering pass (metres): furniture groups within a room.
pub const FIRST_CELL: f32 = 2.0;

/// How a face of a box is seen: its outward normal, and the directions of the image's x
/// (right) and y (up) when the face is viewed from outside. The capture at build time and the
/// textured box at run time both use it, so texels land where they were captured.
pub fn face_frame(face: usize) -> (Vec3, Vec3, Vec3) {
    let (axis, sign) = FACES[face % 6];
    let mut n = Vec3::ZERO;
    n[axis] = sign;
    let up_hint = if axis == 1 { Vec3::Z } else { Vec3::Y };
    let forward = -n;
    let right = forward.cross(up_hint).normalize();
    let up = right.cross(forward);
    (n, right, up)
}

/// Where a world point falls in a face's tile, in 0..1 (u right, v down), for a box `b`.
pub fn face_uv(b: &Aabb, face: usize, p: Vec3) -> [f32; 2] {
    let (_, right, up) = face_frame(face);
    let c = b.center();
    let size = b.size();
    let half = |d: Vec3| (d.abs().dot(size) * 0.5).max(1e-6);
    let x = (p - c).dot(right) / half(right);
    let y = (p - c).dot(up) / half(up);
    [(x + 1.0) * 0.5, (1.0 - y) * 0.5]
}

/// The tile side for a cluster of these bounds (0 = no textured box).
pub fn tile_for(b: &Aabb) -> u32 {
    let side = b.size().max_element();
    if side < MIN_TEXTURED_SIZE {
        return 0;
    }
    ((side * TEXELS_PER_METRE).round() as u32).clamp(TILE_RANGE.0, TILE_RANGE.1)
}

/// One object to paint into an impostor: its geometry (in its own coordinates), placement and
/// material colour; `key` names the geometry so a painter can upload it once.
#[derive(Debug, Clone, Copy)]
pub struct PaintItem<'a> {
    /// Stable name of the geometry (definition and LOD).
    pub key: (u32, u32),
    /// The geometry.
    pub mesh: &'a Mesh,
    /// Object-to-world transform.
    pub transform: Mat4,
    /// Material colour (linear RGBA).
    pub color: [f32; 4],
    /// The material's texture (its index in the model, and the image) when the mesh has
    /// coordinates for it.
    pub texture: Option<(u32, &'a crate::texture::TextureImage)>,
    /// How the material's alpha is used.
    pub alpha: crate::texture::AlphaMode,
    /// The material's emissive colour, lighting and sides.
    pub surface: crate::model::Surface,
}

/// Paints impostor textures at build time (Maciel §5.2.2: orthographic captures of the real
/// objects, on a transparent background). The CLI hands `portico build` the client's wgpu
/// renderer; the data crate itself draws nothing.
pub trait ImpostorPainter {
    /// The six face views of `items` filling `bounds` ([`face_frame`], [`FACES`] order), each
    /// `tile` pixels square, as a 3 × 2 atlas (face `i` at column `i % 3`, row `i / 3`),
    /// encoded as PNG, and each face's average colour (linear RGBA, alpha = covered fraction).
    fn paint(
        &mut self,
        items: &[PaintItem<'_>],
        bounds: &Aabb,
        tile: u32,
    ) -> Result<(Vec<u8>, [[f32; 4]; 6]), String>;
}

/// A cluster's average-colour box (Maciel §5.2): 24 vertices and 12 triangles, each face in its
/// average colour. The colours were captured lit, so the vertices have no normal (the shader
/// then leaves them as they are).
pub fn colour_box(b: &Aabb, colors: &[[f32; 4]; 6]) -> Mesh {
    let mut m = Mesh::default();
    let c = b.center();
    let half = b.size() * 0.5;
    for (face, color) in colors.iter().enumerate() {
        let (n, right, up) = face_frame(face);
        let base = m.vertices.len() as u32;
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = c
                + n * n.abs().dot(half)
                + right * (sx * right.abs().dot(half))
                + up * (sy * up.abs().dot(half));
            m.vertices.push(crate::geometry::Vertex::new(
                p.into(),
                [0.0; 3],
                [color[0], color[1], color[2], 1.0],
            ));
        }
        m.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    m
}

/// One cluster.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClusterNode {
    /// Tight bounds of everything beneath (a bounding-volume hierarchy, as Maciel's octree).
    pub bounds: Aabb,
    /// Parent cluster (`u32::MAX` for the root).
    pub parent: u32,
    /// Child clusters.
    pub nodes: Vec<u32>,
    /// Child instances.
    pub instances: Vec<u32>,
    /// Instances beneath, at any depth.
    pub instance_count: u32,
    /// Average colour (linear RGBA, alpha = covered fraction) of each face's view, [`FACES`]
    /// order: the average-colour box (Maciel §5.2).
    pub face_colors: [[f32; 4]; 6],
    /// Texture segment of the textured box: a 3 × 2 atlas of the six face views (PNG), or
    /// `u32::MAX` when none was captured.
    pub texture: u32,
    /// Pixels per side of one atlas tile.
    pub tile: u32,
}

/// The whole tree.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Hierarchy {
    /// Clusters; children come before their parents, the root last.
    pub nodes: Vec<ClusterNode>,
    /// For every instance, the cluster it hangs under (`u32::MAX` when the model has a single
    /// instance and so no cluster).
    pub instance_parent: Vec<u32>,
}

/// A top-level entry during the build: an instance or a cluster made in an earlier pass.
#[derive(Debug, Clone, Copy)]
enum Item {
    Instance(u32),
    Node(u32),
}

impl Hierarchy {
    /// Clusters `bounds` (one per instance) bottom-up, starting from grid cells of
    /// `cell` metres (doubled each pass).
    pub fn build(bounds: &[Aabb], cell: f32) -> Hierarchy {
        let mut h = Hierarchy {
            nodes: Vec::new(),
            instance_parent: vec![u32::MAX; bounds.len()],
        };
        if bounds.len() < 2 {
            return h;
        }
        let model = bounds.iter().fold(Aabb::EMPTY, |a, b| a.union(b));
        let mut top: Vec<(Item, Aabb)> = bounds
            .iter()
            .enumerate()
            .map(|(i, b)| (Item::Instance(i as u32), *b))
            .collect();
        let mut size = cell.max(1e-3);
        loop {
            let covers_all = (0..3).all(|k| model.max[k] - model.min[k] <= size);
            top = h.pass(top, &model, size, covers_all);
            if top.len() <= 1 {
                break;
            }
            size *= 2.0;
        }
        h
    }

    /// One pass: groups the top-level items completely inside each grid cell of side `size`
    /// (all of them when `last`). Returns the new top level.
    fn pass(
        &mut self,
        top: Vec<(Item, Aabb)>,
        model: &Aabb,
        size: f32,
        last: bool,
    ) -> Vec<(Item, Aabb)> {
        let mut cells: std::collections::BTreeMap<[i64; 3], Vec<(Item, Aabb)>> =
            std::collections::BTreeMap::new();
        let mut straddling = Vec::new();
        for (item, b) in top {
            let key = |p: [f32; 3]| {
                let mut k = [0i64; 3];
                for a in 0..3 {
                    k[a] = ((p[a] - model.min[a]) / size).floor() as i64;
                }
                k
            };
            let (lo, hi) = (key(b.min), key(b.max));
            if last || lo == hi {
                cells
                    .entry(if last { [0; 3] } else { lo })
                    .or_default()
                    .push((item, b));
            } else {
                straddling.push((item, b));
            }
        }
        let mut next = straddling;
        for (_, items) in cells {
            if items.len() < 2 {
                next.extend(items);
                continue;
            }
            let id = self.nodes.len() as u32;
            let mut node = ClusterNode {
                bounds: items.iter().fold(Aabb::EMPTY, |a, (_, b)| a.union(b)),
                parent: u32::MAX,
                nodes: Vec::new(),
                instances: Vec::new(),
                instance_count: 0,
                face_colors: [[0.0; 4]; 6],
                texture: u32::MAX,
                tile: 0,
            };
            for (item, _) in &items {
                match *item {
                    Item::Instance(i) => {
                        node.instances.push(i);
                        node.instance_count += 1;
                        self.instance_parent[i as usize] = id;
                    }
                    Item::Node(n) => {
                        node.nodes.push(n);
                        node.instance_count += self.nodes[n as usize].instance_count;
                        self.nodes[n as usize].parent = id;
                    }
                }
            }
            next.push((Item::Node(id), node.bounds));
            self.nodes.push(node);
        }
        next
    }

    /// The root cluster, if any.
    pub fn root(&self) -> Option<u32> {
        self.nodes.len().checked_sub(1).map(|r| r as u32)
    }

    /// Every instance beneath a node, depth first.
    pub fn instances_under(&self, node: u32) -> Vec<u32> {
        let mut out = Vec::new();
        let mut stack = vec![node];
        while let Some(n) = stack.pop() {
            let Some(c) = self.nodes.get(n as usize) else {
                continue;
            };
            out.extend(&c.instances);
            stack.extend(&c.nodes);
        }
        out
    }

    /// Checks the invariants: every instance under exactly one cluster, parent links agree
    /// with child lists, children come before parents, bounds contain the children, every
    /// cluster has at least two children (so Maciel's cost rule holds: a box stand-in costs
    /// [`BOX_TRIANGLES`], less than any two children's cheapest, which cost at least that much
    /// each), and one root.
    pub fn check(&self, instance_bounds: &[Aabb]) -> Result<(), String> {
        if self.instance_parent.len() != instance_bounds.len() {
            return Err("instance_parent does not list every instance".into());
        }
        if instance_bounds.len() < 2 {
            return Ok(());
        }
        let mut seen = vec![0u32; instance_bounds.len()];
        let mut roots = 0;
        for (id, n) in self.nodes.iter().enumerate() {
            if n.nodes.len() + n.instances.len() < 2 {
                return Err(format!("cluster {id} has fewer than two children"));
            }
            if n.parent == u32::MAX {
                roots += 1;
            } else if n.parent as usize <= id || n.parent as usize >= self.nodes.len() {
                return Err(format!("cluster {id} has parent {} out of order", n.parent));
            }
            for &i in &n.instances {
                let b = instance_bounds
                    .get(i as usize)
                    .ok_or_else(|| format!("cluster {id} lists missing instance {i}"))?;
                seen[i as usize] += 1;
                if self.instance_parent[i as usize] != id as u32 {
                    return Err(format!("instance {i}'s parent is not cluster {id}"));
                }
                if !n.bounds.contains_box(b) {
                    return Err(format!("cluster {id} does not contain instance {i}"));
                }
            }
            for &c in &n.nodes {
                let child = self
                    .nodes
                    .get(c as usize)
                    .ok_or_else(|| format!("cluster {id} lists missing cluster {c}"))?;
                if child.parent != id as u32 || c as usize >= id {
                    return Err(format!("cluster {c}'s parent link disagrees with {id}"));
                }
                if !n.bounds.contains_box(&child.bounds) {
                    return Err(format!("cluster {id} does not contain cluster {c}"));
                }
            }
        }
        if let Some(i) = seen.iter().position(|&s| s != 1) {
            return Err(format!("instance {i} is under {} clusters", seen[i]));
        }
        if roots != 1 {
            return Err(format!("{roots} roots"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bx(x: f32, z: f32, s: f32) -> Aabb {
        Aabb {
            min: [x, 0.0, z],
            max: [x + s, s, z + s],
        }
    }

    #[test]
    fn neighbours_cluster_first_and_everything_ends_under_one_root() {
        // Two tight groups far apart, and a lone object.
        let b = vec![
            bx(0.0, 0.0, 0.5),
            bx(0.6, 0.0, 0.5),
            bx(0.0, 0.6, 0.5),
            bx(20.0, 20.0, 0.5),
            bx(20.6, 20.0, 0.5),
            bx(40.0, 0.0, 0.5),
        ];
        let h = Hierarchy::build(&b, 2.0);
        h.check(&b).unwrap();
        // The first clusters are the two tight groups.
        let first: Vec<Vec<u32>> = h.nodes[..2]
            .iter()
            .map(|n| {
                let mut v = n.instances.clone();
                v.sort();
                v
            })
            .collect();
        assert!(first.contains(&vec![0, 1, 2]), "{first:?}");
        assert!(first.contains(&vec![3, 4]), "{first:?}");
        let root = h.root().unwrap();
        assert_eq!(h.nodes[root as usize].instance_count, 6);
        let mut all = h.instances_under(root);
        all.sort();
        assert_eq!(all, (0..6).collect::<Vec<u32>>());
    }

    #[test]
    fn one_instance_needs_no_cluster_and_check_catches_damage() {
        let one = vec![bx(0.0, 0.0, 1.0)];
        let h = Hierarchy::build(&one, 1.0);
        assert!(h.nodes.is_empty());
        h.check(&one).unwrap();
        let b = vec![bx(0.0, 0.0, 1.0), bx(1.5, 0.0, 1.0), bx(3.0, 0.0, 1.0)];
        let mut h = Hierarchy::build(&b, 4.0);
        h.check(&b).unwrap();
        let i = h.nodes[0].instances[0];
        h.nodes[0].instances.push(i);
        assert!(h.check(&b).is_err(), "an instance listed twice");
    }
}
