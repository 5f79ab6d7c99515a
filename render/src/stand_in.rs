//! What stands in for a cluster the traversal drew as a box (Maciel & Shirley 1995, §6.4): its
//! textured box where the atlas tile is resident, else a box in the cluster's average face
//! colours (Selçuk's far boxes), made on the GPU the first frame it is wanted and dropped when
//! no frame wants it. Shared by every front end that runs the cluster traversal.

use crate::{Draw, GpuImpostor, GpuMesh, Renderer};
use glam::Mat4;
use portico_client::cluster::Stand;
use portico_data::geometry::encode_geometry;
use portico_data::hierarchy::{Hierarchy, colour_box};
use std::collections::{HashMap, HashSet};

/// The colour boxes on the GPU, by hierarchy node.
#[derive(Debug, Default)]
pub struct StandIns {
    colour: HashMap<u32, GpuMesh>,
}

impl StandIns {
    /// Makes the colour boxes of the frame's `boxes` (hierarchy node, how it stands) that are
    /// not yet on the GPU, and drops those no longer wanted.
    pub fn update(&mut self, h: &Hierarchy, boxes: &[(u32, Stand)], r: &Renderer) {
        let wanted: HashSet<u32> = boxes.iter().map(|b| b.0).collect();
        self.colour.retain(|n, _| wanted.contains(n));
        for &(n, _) in boxes {
            if let std::collections::hash_map::Entry::Vacant(e) = self.colour.entry(n) {
                let Some(node) = h.nodes.get(n as usize) else {
                    continue;
                };
                let mesh = encode_geometry(&colour_box(&node.bounds, &node.face_colors));
                if let Ok(gpu) = r.upload(&mesh) {
                    e.insert(gpu);
                }
            }
        }
    }

    /// Adds the colour boxes to `draws` and returns the textured boxes to draw: a box that
    /// stands textured with its atlas tile resident (`impostor` gives it by segment) is drawn
    /// textured, any other in its colours.
    pub fn draws<'c>(
        &'c self,
        h: &Hierarchy,
        boxes: &[(u32, Stand)],
        impostor: impl Fn(u32) -> Option<&'c GpuImpostor>,
        draws: &mut Vec<Draw<'c>>,
    ) -> Vec<&'c GpuImpostor> {
        let mut textured = Vec::new();
        for &(n, stand) in boxes {
            let Some(node) = h.nodes.get(n as usize) else {
                continue;
            };
            match (stand, impostor(node.texture)) {
                (Stand::Textured, Some(i)) => textured.push(i),
                _ => {
                    if let Some(mesh) = self.colour.get(&n) {
                        draws.push(Draw::new(mesh, Mat4::IDENTITY, [1.0; 4]));
                    }
                }
            }
        }
        textured
    }
}
