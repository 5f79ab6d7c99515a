//! Placing a glTF's instances: the frame settled from their pieces ([`frame::settle`]), the
//! local origin, and the strays.

use super::{Importer, Placed, extras, name_of};
use crate::bulk::{DBox, MAX_COORDINATE, bulk, local_origin};
use crate::frame::SourceFrame;
use crate::import::frame::{self, Piece, pieces_of};
use crate::model::Instance;
use glam::{DMat4, DVec3, Vec3};
use std::collections::HashMap;

/// Pieces read for the evidence at most: instances are spread out until their pieces fit.
const MAX_PIECES: usize = 1_000_000;

impl Importer<'_> {
    /// Settles the frame (converting the instances to it), moves them to the model's local
    /// origin and names the strays.
    pub(super) fn place(
        &mut self,
        mut placed: Vec<Placed>,
        warnings: &mut Vec<String>,
    ) -> Result<(), String> {
        let (frame, said) = frame::settle(
            &self.pieces(&placed),
            &SourceFrame::metres_y_up(),
            false,
            &self.options,
        );
        warnings.extend(said);
        if !frame.is_identity() {
            let to_metres = frame.to_metres_y_up();
            placed
                .iter_mut()
                .for_each(|p| p.world = to_metres * p.world);
        }
        self.model.frames.push(frame);
        let mut boxes = Vec::with_capacity(placed.len());
        for p in &placed {
            let local = self.model.defs[p.def as usize].lods[0].bounds();
            let mut b = DBox::EMPTY;
            if !local.is_empty() {
                for i in 0..8 {
                    let corner = Vec3::new(
                        if i & 1 == 0 {
                            local.min[0]
                        } else {
                            local.max[0]
                        },
                        if i & 2 == 0 {
                            local.min[1]
                        } else {
                            local.max[1]
                        },
                        if i & 4 == 0 {
                            local.min[2]
                        } else {
                            local.max[2]
                        },
                    );
                    b.include(p.world.transform_point3(corner.as_dvec3()));
                }
            }
            let far = b.min.abs().max(b.max.abs()).max_element();
            if !b.is_empty() && (far.is_nan() || far > MAX_COORDINATE) {
                let node = &self.root.nodes[p.node];
                return Err(format!(
                    "node {}{}: its mesh reaches {far:.3e} m from the origin, beyond ±{MAX_COORDINATE:.0e} m",
                    p.node,
                    name_of(&node.name)
                ));
            }
            boxes.push(b);
        }
        let bulk = bulk(&boxes);
        for &s in &bulk.strays {
            let node = &self.root.nodes[placed[s].node];
            warnings.push(format!(
                "node {}{} lies {:.0} m from the rest of the model: it gets a cell of its own",
                placed[s].node,
                name_of(&node.name),
                boxes[s].distance(&bulk.bounds)
            ));
        }
        let origin = local_origin(&bulk.bounds);
        self.model.origin = origin.to_array();
        let shift = DMat4::from_translation(-origin);
        for p in placed {
            let node = &self.root.nodes[p.node];
            let (occluder, tags) =
                extras(&node.extras).map_err(|e| format!("node {}: {e}", p.node))?;
            self.model.instances.push(Instance {
                name: node
                    .name
                    .clone()
                    .unwrap_or_else(|| format!("node{}", p.node)),
                def: p.def,
                transform: (shift * p.world).as_mat4(),
                material: self.model.defs[p.def as usize].material,
                occluder,
                tags,
            });
        }
        Ok(())
    }

    /// The connected parts of the placed definitions ([`frame::pieces_of`]), each definition
    /// cut once; instances evenly spread, at most [`frame::MAX_SAMPLED`] of them and
    /// [`MAX_PIECES`] pieces in all.
    fn pieces(&self, placed: &[Placed]) -> Vec<Piece> {
        let mut own: HashMap<u32, Vec<Piece>> = HashMap::new();
        let stride = placed.len().div_ceil(frame::MAX_SAMPLED).max(1);
        let sampled: Vec<&Placed> = placed.iter().step_by(stride).collect();
        for p in &sampled {
            own.entry(p.def).or_insert_with(|| {
                let mesh = &self.model.defs[p.def as usize].lods[0];
                let positions: Vec<DVec3> = mesh
                    .vertices
                    .iter()
                    .map(|v| Vec3::from(v.position).as_dvec3())
                    .collect();
                pieces_of(&positions, &mesh.indices, &DMat4::IDENTITY)
            });
        }
        let total: usize = sampled.iter().map(|p| own[&p.def].len()).sum();
        let thin = total.div_ceil(MAX_PIECES).max(1);
        let mut out = Vec::with_capacity(total / thin + 1);
        for p in sampled.into_iter().step_by(thin) {
            let scale = p
                .world
                .to_scale_rotation_translation()
                .0
                .abs()
                .max_element();
            out.extend(own[&p.def].iter().map(|q| q.placed_scaled(&p.world, scale)));
        }
        out
    }
}
