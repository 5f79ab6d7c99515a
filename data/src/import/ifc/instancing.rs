//! One object definition per shared shape and one instance per occurrence (Funkhouser §3.1:
//! definitions shared by instances, Fig. 3.4).
//!
//! BIM models are mostly repeated families: a chair, a window, a door type placed hundreds of
//! times, each as an `IfcMappedItem` of one `IfcRepresentationMap`. The geometry kernel bakes
//! every occurrence into world space, but tells which shape each came from and where it put it
//! (its `InstanceMeta`: the representation map, or a hash of a direct solid's geometry, and
//! the placement). Occurrences of one shape with the same colours become instances of the
//! first one's definition, moved by `placement_k · placement_0⁻¹`. Each copy is checked against
//! its own baked vertices (within [`TOLERANCE`]) before it is shared, so a shape the kernel cut
//! differently (openings), or a mirrored one, keeps its own definition.

use glam::{DMat4, DVec3};
use std::collections::HashMap;

/// Definitions of one shape and colours tried for each occurrence at most (shapes the kernel
/// cut differently each keep their own, and each is not tried again and again).
pub const MAX_TEMPLATES: usize = 8;

/// How far (metres) a shared copy's vertices may lie from the occurrence's own.
pub const TOLERANCE: f64 = 1e-4;

/// Where a product's shape came from, as the kernel said.
#[derive(Debug, Clone, PartialEq)]
pub struct Occurrence {
    /// The shape of each of its meshes (a representation map's id, or a geometry hash).
    pub shapes: Vec<u128>,
    /// The kernel's placement of the first mesh (its frame: the file's, Z up, metres).
    pub placement: DMat4,
}

/// What one product becomes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Share {
    /// A definition of its own.
    Own,
    /// An instance of product `of`'s definition, moved by `moved` (in the model's frame).
    Copy {
        /// The product whose definition it shares.
        of: usize,
        /// Its world transform relative to that product's.
        moved: DMat4,
    },
}

/// One product as the sharing sees it: its shape's origin, its vertices (world, the model's
/// frame), its triangles and each vertex's colour.
pub struct Shape<'a> {
    /// Where the kernel says the shape came from; `None` when it is the product's own.
    pub occurrence: Option<&'a Occurrence>,
    /// World positions.
    pub positions: &'a [DVec3],
    /// Triangles.
    pub indices: &'a [u32],
    /// Linear colours.
    pub colours: &'a [[f32; 4]],
}

/// What occurrences must have in common to share: their shapes and their colours.
type Key = (Vec<u128>, Vec<[u32; 4]>);

/// Decides for each product whether it shares another's definition. `kernel_to_model` takes
/// the kernel's frame to the model's (Z up to Y up, and any unit the user gave).
pub fn share(shapes: &[Shape], kernel_to_model: &DMat4) -> Vec<Share> {
    let back = kernel_to_model.inverse();
    // Per key, up to MAX_TEMPLATES products whose definitions others may share, each with
    // its placement's inverse.
    let mut templates: HashMap<Key, Vec<(usize, DMat4)>> = HashMap::new();
    let mut out = Vec::with_capacity(shapes.len());
    for (k, s) in shapes.iter().enumerate() {
        let Some(occ) = s.occurrence else {
            out.push(Share::Own);
            continue;
        };
        let key = (occ.shapes.clone(), colour_runs(s.colours));
        let candidates = templates.entry(key).or_default();
        let found = candidates.iter().find_map(|&(t, first_inverse)| {
            let moved = *kernel_to_model * occ.placement * first_inverse * back;
            fits(&shapes[t], s, &moved).then_some(Share::Copy { of: t, moved })
        });
        match found {
            Some(share) => out.push(share),
            None => {
                if candidates.len() < MAX_TEMPLATES {
                    candidates.push((k, occ.placement.inverse()));
                }
                out.push(Share::Own);
            }
        }
    }
    out
}

/// Whether `moved` takes the template's vertices onto the copy's, without mirroring.
fn fits(template: &Shape, copy: &Shape, moved: &DMat4) -> bool {
    template.positions.len() == copy.positions.len()
        && template.indices == copy.indices
        && moved.determinant() > 0.0
        && moved.is_finite()
        && template
            .positions
            .iter()
            .zip(copy.positions)
            .all(|(a, b)| moved.transform_point3(*a).distance(*b) <= TOLERANCE)
}

/// The colours run by run (one entry per change), as exact bits.
fn colour_runs(colours: &[[f32; 4]]) -> Vec<[u32; 4]> {
    let mut runs: Vec<[u32; 4]> = Vec::new();
    for c in colours {
        let bits = c.map(f32::to_bits);
        if runs.last() != Some(&bits) {
            runs.push(bits);
        }
    }
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(at: DVec3) -> Vec<DVec3> {
        vec![at, at + DVec3::X, at + DVec3::Y]
    }

    #[test]
    fn occurrences_of_one_shape_share_and_a_cut_one_does_not() {
        let occ = |x: f64| Occurrence {
            shapes: vec![7],
            placement: DMat4::from_translation(DVec3::new(x, 0.0, 0.0)),
        };
        let (o0, o1, o2) = (occ(0.0), occ(5.0), occ(9.0));
        let p0 = tri(DVec3::ZERO);
        let p1 = tri(DVec3::new(5.0, 0.0, 0.0));
        // The third was cut: one vertex moved.
        let mut p2 = tri(DVec3::new(9.0, 0.0, 0.0));
        p2[2].y = 0.5;
        let idx = [0, 1, 2];
        let white = [[1.0; 4]; 3];
        let shapes = [(&o0, &p0), (&o1, &p1), (&o2, &p2)].map(|(o, p)| Shape {
            occurrence: Some(o),
            positions: p,
            indices: &idx,
            colours: &white,
        });
        let s = share(&shapes, &DMat4::IDENTITY);
        assert_eq!(s[0], Share::Own);
        match s[1] {
            Share::Copy { of: 0, moved } => {
                assert!((moved.w_axis.x - 5.0).abs() < 1e-12, "{moved}")
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(s[2], Share::Own);
    }
}
