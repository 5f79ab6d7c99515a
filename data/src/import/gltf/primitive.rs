//! One glTF primitive as a triangle list (glTF 2.0 §3.7.2): its attributes read through the
//! checked [`super::accessor`] reader, morph targets applied at their weights (§3.7.2.2), skinned
//! at the skeleton's rest pose (§3.7.3), strips and fans turned into lists.

use super::super::mesh_from_streams;
use super::accessor::{Accessors, Semantic};
use crate::geometry::Mesh;
use ::gltf::json;
use glam::{DMat4, DVec3};
use json::validation::Checked;

/// One primitive as a triangle list; `None` for points and lines.
pub(super) fn primitive(
    root: &json::Root,
    acc: &mut Accessors<'_>,
    mesh: usize,
    p: usize,
    weights: &[f32],
    skin: Option<&[DMat4]>,
    uv: Option<super::material::UvMap>,
) -> Result<Option<Mesh>, String> {
    use json::mesh::{Mode, Semantic as S};
    let prim = &root.meshes[mesh].primitives[p];
    let Checked::Valid(mode) = prim.mode else {
        return Err("unknown primitive mode".into());
    };
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        return Ok(None);
    }
    let attr = |s: S| prim.attributes.get(&Checked::Valid(s)).map(|a| a.value());
    let pos_acc = attr(S::Positions).ok_or("no POSITION attribute")?;
    let (pos, _) = acc.floats(pos_acc, Semantic::Position)?;
    let mut positions: Vec<[f32; 3]> = pos.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let count = positions.len();
    let same_count = |a: usize, what: &str, n: usize| {
        if n == count {
            Ok(())
        } else {
            Err(format!(
                "accessor {a} ({what}) has {n} elements, POSITION (accessor {pos_acc}) has {count}"
            ))
        }
    };
    let mut normals: Option<Vec<[f32; 3]>> = match attr(S::Normals) {
        Some(a) => {
            let (v, _) = acc.floats(a, Semantic::Normal)?;
            same_count(a, "NORMAL", v.len() / 3)?;
            Some(v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
        }
        None => None,
    };
    let factor = prim
        .material
        .and_then(|m| root.materials.get(m.value()))
        .map_or([1.0; 4], |m| m.pbr_metallic_roughness.base_color_factor.0);
    let colors: Vec<[f32; 4]> = match attr(S::Colors(0)) {
        Some(a) => {
            let (v, k) = acc.floats(a, Semantic::Color)?;
            same_count(a, "COLOR_0", v.len() / k)?;
            v.chunks_exact(k)
                .map(|c| {
                    let alpha = if k == 4 { c[3] } else { 1.0 };
                    [
                        c[0] * factor[0],
                        c[1] * factor[1],
                        c[2] * factor[2],
                        alpha * factor[3],
                    ]
                })
                .collect()
        }
        None => vec![factor; count],
    };
    for (t, target) in prim.targets.iter().flatten().enumerate() {
        let w = weights.get(t).copied().unwrap_or(0.0);
        if w == 0.0 {
            continue;
        }
        if let Some(a) = target.positions {
            let (d, _) = acc.floats(a.value(), Semantic::Target)?;
            same_count(a.value(), "morph target POSITION", d.len() / 3)?;
            for (p, d) in positions.iter_mut().zip(d.chunks_exact(3)) {
                (0..3).for_each(|k| p[k] += w * d[k]);
            }
        }
        if let (Some(a), Some(ns)) = (target.normals, normals.as_mut()) {
            let (d, _) = acc.floats(a.value(), Semantic::Target)?;
            same_count(a.value(), "morph target NORMAL", d.len() / 3)?;
            for (n, d) in ns.iter_mut().zip(d.chunks_exact(3)) {
                (0..3).for_each(|k| n[k] += w * d[k]);
            }
        }
    }
    if let Some(matrices) = skin {
        let (j, w) = (attr(S::Joints(0)), attr(S::Weights(0)));
        let (Some(j), Some(w)) = (j, w) else {
            return Err("a skinned mesh without JOINTS_0 and WEIGHTS_0".into());
        };
        let (joints, _) = acc.integers(j, Semantic::Joints)?;
        let (wts, _) = acc.floats(w, Semantic::Weights)?;
        same_count(j, "JOINTS_0", joints.len() / 4)?;
        same_count(w, "WEIGHTS_0", wts.len() / 4)?;
        for v in 0..count {
            let mut m = DMat4::ZERO;
            let mut total = 0.0;
            for k in 0..4 {
                let (ji, wk) = (joints[v * 4 + k] as usize, wts[v * 4 + k] as f64);
                if wk == 0.0 {
                    continue;
                }
                let jm = matrices.get(ji).ok_or_else(|| {
                    format!(
                        "accessor {j} (JOINTS_0): joint {ji} of {} in vertex {v}",
                        matrices.len()
                    )
                })?;
                m += *jm * wk;
                total += wk;
            }
            let m = if total > 0.0 {
                m * (1.0 / total)
            } else {
                matrices[0]
            };
            let p = m.transform_point3(DVec3::from(positions[v].map(f64::from)));
            positions[v] = p.as_vec3().into();
            if let Some(ns) = normals.as_mut() {
                let n = m.transform_vector3(DVec3::from(ns[v].map(f64::from)));
                ns[v] = n.as_vec3().into();
            }
        }
    }
    let indices = match prim.indices {
        Some(a) => {
            let i = acc.indices(a.value())?;
            if mode == Mode::Triangles && i.len() % 3 != 0 {
                return Err(format!(
                    "accessor {} (indices): {} indices is not a whole number of triangles",
                    a.value(),
                    i.len()
                ));
            }
            if let Some(bad) = i.iter().find(|&&x| x as usize >= count) {
                return Err(format!(
                    "accessor {} (indices): index {bad} is out of range for {count} vertices",
                    a.value()
                ));
            }
            i
        }
        None => {
            if mode == Mode::Triangles && !count.is_multiple_of(3) {
                return Err(format!(
                    "{count} vertices without indices is not a whole number of triangles"
                ));
            }
            (0..count as u32).collect()
        }
    };
    let indices = match mode {
        Mode::TriangleStrip => strip_to_list(&indices),
        Mode::TriangleFan => fan_to_list(&indices),
        _ => indices,
    };
    let mut mesh = mesh_from_streams(&positions, normals.as_deref(), &colors, indices)?;
    // A textured material's coordinates, transformed; a primitive without them is drawn in its
    // colour alone.
    if let Some(map) = uv
        && let Some(a) = attr(S::TexCoords(map.set))
    {
        let (v, _) = acc.floats(a, Semantic::TexCoord)?;
        same_count(a, "TEXCOORD", v.len() / 2)?;
        mesh.uvs = map.coordinates(&v);
        mesh.validate()?;
    }
    Ok(Some(mesh))
}

fn strip_to_list(s: &[u32]) -> Vec<u32> {
    (2..s.len())
        .flat_map(|i| {
            if i % 2 == 0 {
                [s[i - 2], s[i - 1], s[i]]
            } else {
                [s[i - 1], s[i - 2], s[i]]
            }
        })
        .collect()
}

fn fan_to_list(s: &[u32]) -> Vec<u32> {
    (2..s.len()).flat_map(|i| [s[0], s[i - 1], s[i]]).collect()
}
