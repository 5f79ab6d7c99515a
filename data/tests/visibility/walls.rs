//! Random walls and slabs with holes, and models of boxes: what the stab lists must list behind
//! them.

use super::*;

/// Whether `p` lies inside the convex polygon (counter-clockwise), `margin` inside its edges.
pub(crate) fn in_convex(poly: &[[f64; 2]], p: [f64; 2], margin: f64) -> bool {
    (0..poly.len()).all(|k| {
        let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
        let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
        let cross = ex * (p[1] - a[1]) - ey * (p[0] - a[0]);
        cross > margin * (ex * ex + ey * ey).sqrt()
    })
}

/// A slab between `lo` and `hi` along axis `t`, its faces `faces[0]` and `faces[1]` (in the
/// other two axes, u then v) and closed all round along the outline and every hole's rim.
/// `twice` writes each face triangle again, reversed (a two-sided export).
fn slab_mesh(
    t: usize,
    (lo, hi): (f32, f32),
    faces: [&[[[f32; 2]; 3]]; 2],
    rims: &[Vec<[f64; 2]>],
    twice: bool,
) -> Mesh {
    let (u, v) = ((t + 1) % 3, (t + 2) % 3);
    let at = |q: [f32; 2], w: f32| {
        let mut p = [0.0f32; 3];
        (p[u], p[v], p[t]) = (q[0], q[1], w);
        Vertex::new(p, [0.0, 1.0, 0.0], [0.6, 0.6, 0.6, 1.0])
    };
    let mut vertices = Vec::new();
    let mut indices = Vec::new();
    let mut tri = |a: Vertex, b: Vertex, c: Vertex, both: bool| {
        let n = vertices.len() as u32;
        vertices.extend([a, b, c]);
        indices.extend([n, n + 1, n + 2]);
        if both {
            indices.extend([n, n + 2, n + 1]);
        }
    };
    for (face, w) in faces.iter().zip([lo, hi]) {
        for f in face.iter() {
            tri(at(f[0], w), at(f[1], w), at(f[2], w), twice);
        }
    }
    for rim in rims {
        for k in 0..rim.len() {
            let (a, b) = (rim[k], rim[(k + 1) % rim.len()]);
            let (a, b) = ([a[0] as f32, a[1] as f32], [b[0] as f32, b[1] as f32]);
            tri(at(a, lo), at(b, lo), at(b, hi), false);
            tri(at(a, lo), at(b, hi), at(a, hi), false);
        }
    }
    Mesh {
        vertices,
        indices,
        uvs: Vec::new(),
    }
}

/// A random convex hole: `n` corners on a circle of radius `r` around `c`, turned by `turn`,
/// counter-clockwise.
fn hole(c: [f64; 2], r: f64, n: usize, turn: f64) -> Vec<[f64; 2]> {
    (0..n)
        .map(|k| {
            let a = turn + std::f64::consts::TAU * k as f64 / n as f64;
            [c[0] + r * a.cos(), c[1] + r * a.sin()]
        })
        .collect()
}

/// One random wall (`t` = 0: across x, 0.2 m thick, in a 10 × 3 × 8 m box) or slab (`t` = 1:
/// across y at 1.5 m, in a 8 × 3.5 × 8 m box) with holes, a cube just behind each hole and
/// more scattered on both sides; the precompute alone must list everything a ray sees.
fn wall_with_holes_is_conservative(
    t: usize,
    slots: &[(bool, f64, usize, f64, f64, f64)],
    extra: &[[f64; 2]],
    twice: bool,
    split: usize,
) -> Result<(), TestCaseError> {
    let (bounds, (lo, hi), (w, h)) = if t == 0 {
        (
            Aabb {
                min: [0.0; 3],
                max: [10.0, 3.0, 8.0],
            },
            (5.0f32, 5.2f32),
            (3.0f64, 8.0f64), // u = y, v = z
        )
    } else {
        (
            Aabb {
                min: [0.0; 3],
                max: [8.0, 3.5, 8.0],
            },
            (1.5, 1.7),
            (8.0, 8.0), // u = z, v = x
        )
    };
    // Holes in a row of slots along v, each inside its own slot, clear of the outline.
    let slot = h / slots.len() as f64;
    let mut holes = Vec::new();
    for (k, &(used, r, n, turn, du, dv)) in slots.iter().enumerate() {
        if !used {
            continue;
        }
        let r = r.min(0.4 * slot).min(0.4 * w);
        let c = [
            r + 0.05 + du * (w - 2.0 * r - 0.1),
            slot * k as f64 + r + 0.05 + dv * (slot - 2.0 * r - 0.1),
        ];
        holes.push(hole(c, r, n, turn));
    }
    let scale = |p: &[f64; 2]| [p[0] * w, p[1] * h];
    let e0: Vec<[f64; 2]> = extra.iter().step_by(2).map(scale).collect();
    let e1: Vec<[f64; 2]> = extra.iter().skip(1).step_by(2).map(scale).collect();
    let (f0, f1) = (
        holed_face(w, h, &holes, &e0, split),
        holed_face(w, h, &holes, &e1, 0),
    );
    let mut rims = holes.clone();
    rims.push(vec![[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]);
    let slab = slab_mesh(t, (lo, hi), [&f0, &f1], &rims, twice);
    // Cubes 0.3 m across: one 0.4 m beyond each hole's centre, and a row on either side.
    let (u, v) = ((t + 1) % 3, (t + 2) % 3);
    let mut cubes = Vec::new();
    for hole in &holes {
        let c = hole
            .iter()
            .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
        let mut p = [0.0f32; 3];
        p[u] = (c[0] / hole.len() as f64) as f32;
        p[v] = (c[1] / hole.len() as f64) as f32;
        p[t] = hi + 0.4;
        cubes.push(Vec3::from(p));
    }
    for k in 0..6 {
        let mut p = bounds.center().to_array();
        p[v] = bounds.min[v] + (k as f32 + 0.5) * (bounds.max[v] - bounds.min[v]) / 6.0;
        p[u] = bounds.min[u] + 0.3 + 0.4 * (bounds.max[u] - bounds.min[u]) * (k % 2) as f32;
        p[t] = if k < 3 { lo - 1.0 } else { hi + 1.5 };
        cubes.push(Vec3::from(p));
    }
    let cube = portico_data::lod::box_mesh(
        &Aabb {
            min: [-0.15; 3],
            max: [0.15; 3],
        },
        [0.8, 0.2, 0.2, 1.0],
    );
    let mut meshes = vec![(slab, Mat4::IDENTITY, true)];
    meshes.extend(
        cubes
            .iter()
            .map(|c| (cube.clone(), Mat4::from_translation(*c), false)),
    );
    let occ = occluder_boxes(meshes.iter().map(|(m, x, tag)| (m, *x, *tag)));
    let world: Vec<Vec<[Vec3; 3]>> = meshes
        .iter()
        .map(|(m, x, _)| {
            m.indices
                .chunks_exact(3)
                .map(|i| {
                    i.iter()
                        .map(|&k| x.transform_point3(Vec3::from(m.vertices[k as usize].position)))
                })
                .map(|mut p| [p.next().unwrap(), p.next().unwrap(), p.next().unwrap()])
                .collect()
        })
        .collect();
    let boxes: Vec<Aabb> = meshes
        .iter()
        .map(|(m, x, _)| m.bounds().transformed(x))
        .collect();
    let p = precompute(&bounds, &occ, &boxes, &|_, _| {}, &|| {});
    let scene = Triangles::new(boxes, world);
    let r = verify_against_triangles(&p.graph, &p.stabs, &scene, 12_000, 11);
    prop_assert_eq!(
        r.false_negatives,
        0,
        "{} holes, examples {:?}, {} occluder faces, {} solids",
        holes.len(),
        r.false_negative_examples,
        occ.faces.len(),
        occ.solids.len()
    );
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 10, .. ProptestConfig::default() })]

    #[test]
    fn walls_and_slabs_of_any_triangulation_with_holes_hide_nothing(
        slab in any::<bool>(),
        slots in prop::collection::vec(
            (any::<bool>(), 0.08f64..0.7, 3usize..9, 0.0f64..6.3, 0.0f64..1.0, 0.0f64..1.0),
            2..5,
        ),
        extra in prop::collection::vec([0.001f64..0.999, 0.001f64..0.999], 0..24),
        twice in any::<bool>(),
        split in 0usize..4,
    ) {
        wall_with_holes_is_conservative(if slab { 1 } else { 0 }, &slots, &extra, twice, split)?;
    }
}
/// A model of boxes: (box, colour, material, tagged occluder), one definition each.
fn boxes_model(parts: &[(Aabb, [f32; 4], u32, bool)], materials: Vec<Material>) -> Model {
    let mut m = Model {
        materials,
        ..Model::default()
    };
    for (k, (b, colour, material, tagged)) in parts.iter().enumerate() {
        m.defs.push(ObjectDef {
            name: format!("part{k}"),
            lods: vec![portico_data::lod::box_mesh(b, *colour)],
            material: *material,
        });
        m.instances.push(Instance {
            name: format!("part{k}"),
            def: k as u32,
            transform: Mat4::IDENTITY,
            material: *material,
            occluder: *tagged,
            tags: Default::default(),
        });
    }
    m
}

#[test]
fn glass_walls_occlude_nothing_unless_tagged() {
    // A tagged floor, an untagged wall-shaped pane across the room, a cube on either side.
    let glass = Material {
        name: "glass".into(),
        base_color: [0.6, 0.8, 0.9, 0.3],
        alpha: AlphaMode::Blend,
        ..Material::default()
    };
    let model = |pane: [f32; 4], material: u32| {
        boxes_model(
            &[
                (
                    Aabb {
                        min: [0.0, -0.2, 0.0],
                        max: [10.0, 0.0, 8.0],
                    },
                    [0.5; 4],
                    0,
                    true,
                ),
                (
                    Aabb {
                        min: [5.0, 0.0, 0.0],
                        max: [5.1, 3.0, 8.0],
                    },
                    pane,
                    material,
                    false,
                ),
                (
                    Aabb {
                        min: [2.0, 0.0, 3.0],
                        max: [3.0, 1.0, 4.0],
                    },
                    [0.8, 0.2, 0.2, 1.0],
                    0,
                    false,
                ),
                (
                    Aabb {
                        min: [7.0, 0.0, 3.0],
                        max: [8.0, 1.0, 4.0],
                    },
                    [0.2, 0.8, 0.2, 1.0],
                    0,
                    false,
                ),
            ],
            vec![Material::default(), glass.clone()],
        )
    };
    let front = Vec3::new(2.5, 1.5, 6.0);
    let lists_far_cube = |b: &Built| {
        let c = b.graph.locate(front).unwrap();
        b.stabs[c as usize].objects().contains(&3)
    };
    // An opaque pane of the same shape is a wall: the far cube is culled from the front.
    let wall = build_model(model([0.5, 0.5, 0.5, 1.0], 0));
    assert!(!lists_far_cube(&wall));
    // Glass by its material, or by translucent vertex colours (IFC), is not.
    for b in [
        build_model(model([0.6, 0.8, 0.9, 1.0], 1)),
        build_model(model([0.6, 0.8, 0.9, 0.3], 0)),
    ] {
        assert!(lists_far_cube(&b));
        assert!(b.unrepaired());
    }
}
