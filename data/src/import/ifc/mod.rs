//! IFC (2x3, 4, 4x3) import through the IFClite stack: `ifc-lite-core` parses the STEP file,
//! `ifc-lite-geometry` meshes each product's body representation, openings subtracted.
//!
//! Only what a product's shape shows is drawn (`representations.rs`: `Body`, never a door's
//! `Clearance`). Every product with a shape (walls, slabs, doors, windows, stairs, furniture,
//! ...) becomes one instance; occurrences of one shape (`IfcMappedItem`s of one representation
//! map, or identical solids) share one definition (`instancing.rs`). Each instance is tagged
//! with what the building model knows of it:
//! `ifc_class` (`IfcWallStandardCase`), `storey` (the `IfcBuildingStorey`'s name), `name` and
//! `guid`. Walls and slabs are the occluders (`occluder`, as the generator's walls and floors
//! are): their own data says they are structure, so no size heuristic guesses it. Opening
//! elements are not drawn (they are the holes), and spaces (`IfcSpace`, the rooms) are not
//! drawn either: their boxes come back in [`Model::spaces`] for the cell subdivision.
//!
//! IFC is Z-up; Portico (like glTF) is Y-up: `(x, y, z)` becomes `(x, z, −y)`. Lengths come
//! in the file's declared unit (`IfcUnitAssignment`), converted to metres by the kernel; the
//! user's `--units` and `--up` override both, and a model whose geometry clearly disagrees with
//! its declared unit gets a warning ([`crate::import::frame`]). Products whose parts carry the
//! shape (assemblies, a roof of slabs) are not reported as lacking one. Colours come
//! from the items' surface styles, else the product's material, else a colour per class;
//! IFC colours are sRGB and are converted to linear. Coordinates are read in f64 and moved to
//! the model's local origin ([`crate::bulk::local_origin`]), so georeferenced files keep their
//! millimetres. A product that does not mesh is skipped with a warning naming it; a file that
//! does not parse at all is one error naming the file.

mod instancing;
mod relations;
mod representations;

use super::frame::{FrameOptions, Piece, pieces_of, settle};
use super::mesh_from_streams;
use crate::bulk::{DBox, MAX_COORDINATE, bulk, local_origin};
use crate::error::{DataError, Result};
use crate::frame::{FrameSource, LengthUnit, SourceFrame, UpAxis};
use crate::geometry::Aabb;
use crate::model::{Instance, Material, Model, ObjectDef, Space};
use glam::{DMat4, DVec3, Mat4, Vec3};
use ifc_lite_core::{EntityDecoder, EntityScanner, has_geometry_by_name};
use ifc_lite_geometry::GeometryRouter;
use instancing::{Occurrence, Shape, Share};
use std::collections::BTreeMap;
use std::path::Path;

pub use relations::{Relations, Storey};

/// Classes whose products occlude: walls and slabs (floors, roofs, landings).
const OCCLUDER_CLASSES: [&str; 5] = [
    "IFCWALL",
    "IFCWALLSTANDARDCASE",
    "IFCWALLELEMENTEDCASE",
    "IFCSLAB",
    "IFCSLABSTANDARDCASE",
];

/// Classes with a shape that are not drawn: holes (and what cuts them), rooms, zones and
/// helpers.
const NOT_DRAWN: [&str; 8] = [
    "IFCOPENINGELEMENT",
    "IFCOPENINGSTANDARDCASE",
    "IFCVOIDINGFEATURE",
    "IFCEARTHWORKSCUT",
    "IFCSPACE",
    "IFCSPATIALZONE",
    "IFCVIRTUALELEMENT",
    "IFCANNOTATION",
];

/// Spatial structure that may or may not have a shape of its own.
const SPATIAL: [&str; 3] = ["IFCSITE", "IFCBUILDING", "IFCBUILDINGSTOREY"];

/// Imports an IFC file, in the unit and up axis `options` give, else the file's.
pub fn import(path: &Path, options: &FrameOptions) -> Result<Model> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    import_slice(&bytes, options).map_err(|e| DataError::import(path, e))
}

/// One product's mesh before the model moves to its local origin: Y-up world positions in
/// f64, normals, linear colours, indices.
struct Part {
    id: u32,
    class: String,
    name: String,
    guid: String,
    positions: Vec<DVec3>,
    normals: Vec<[f32; 3]>,
    colours: Vec<[f32; 4]>,
    indices: Vec<u32>,
    /// Where the kernel says its shape came from, when it can be shared.
    occurrence: Option<Occurrence>,
}

/// Imports IFC bytes (a STEP physical file). The error is one line naming what is wrong. A
/// panic in the IFC kernel is caught: on one product it costs that product (warned), anywhere
/// else it is the error.
pub fn import_slice(bytes: &[u8], options: &FrameOptions) -> Result<Model, String> {
    std::panic::catch_unwind(|| import_unguarded(bytes, options)).unwrap_or_else(|p| {
        Err(format!(
            "the IFC kernel failed on this file: {}",
            panic_text(p.as_ref())
        ))
    })
}

/// The message of a caught panic.
fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into())
}

fn import_unguarded(bytes: &[u8], options: &FrameOptions) -> Result<Model, String> {
    if !bytes.starts_with(b"ISO-10303-21") {
        return Err("not an IFC file: it does not start with ISO-10303-21".into());
    }
    let content = String::from_utf8_lossy(bytes);
    let body = representations::body_only(&content);
    let content: &str = &body.content;
    let rel = relations::scan(content);
    let mut decoder = EntityDecoder::new(content);
    let router = GeometryRouter::with_units(&content, &mut decoder);
    let mut products = Vec::new();
    let mut spaces = Vec::new();
    let mut scanner = EntityScanner::new(content);
    while let Some((id, ty, _, _)) = scanner.next_entity() {
        let ty = ty.to_ascii_uppercase();
        if ty == "IFCSPACE" {
            spaces.push(id);
        } else if has_geometry_by_name(&ty) && !NOT_DRAWN.contains(&ty.as_str()) {
            products.push((id, ty));
        }
    }
    if products.is_empty() {
        return Err("contains no building elements with a shape".into());
    }
    let mut warnings = Vec::new();
    if !bytes.trim_ascii_end().ends_with(b"END-ISO-10303-21;") {
        warnings.push(format!(
            "the file does not end with END-ISO-10303-21: it looks truncated, and only the {} \
             product(s) before the cut are read",
            products.len()
        ));
    }
    let mut parts = Vec::new();
    let mut failed = Vec::new();
    let mut empty = Vec::new();
    for (id, ty) in &products {
        let meshed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            mesh_product(*id, ty, &router, &mut decoder, &rel)
        }))
        .unwrap_or_else(|p| Err(panic_text(p.as_ref())));
        match meshed {
            Ok(Some(p)) => parts.push(p),
            // A site or building without a shape of its own is normal, and so is a product
            // whose parts carry its shape or whose shape only describes it (a clearance).
            Ok(None)
                if SPATIAL.contains(&ty.as_str())
                    || rel.wholes.contains(id)
                    || body.shapeless.contains(id) => {}
            Ok(None) => empty.push(format!("#{id} {ty}")),
            Err(e) => failed.push(format!("#{id} {ty}: {e}")),
        }
    }
    if parts.is_empty() {
        return Err(match failed.first() {
            Some(f) => format!("no product meshed; the first: {f}"),
            None => format!("no product has triangles ({} have no shape)", empty.len()),
        });
    }
    if !empty.is_empty() {
        warnings.push(format!(
            "{} product(s) have no triangles and are left out: {}",
            empty.len(),
            empty.iter().take(5).cloned().collect::<Vec<_>>().join(", ")
        ));
    }
    if !failed.is_empty() {
        warnings.push(format!(
            "{} product(s) did not mesh and are left out: {}",
            failed.len(),
            failed
                .iter()
                .take(5)
                .cloned()
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
    let (frame, kernel_to_model) =
        settle_frame(&mut parts, router.unit_scale(), options, &mut warnings);
    if body.left_out > 0 {
        tracing::debug!(
            "{} representation(s) that describe rather than show (clearances, axes, boxes) left out",
            body.left_out
        );
    }
    let boxes: Vec<DBox> = parts
        .iter()
        .map(|p| {
            let mut b = DBox::EMPTY;
            p.positions.iter().for_each(|q| b.include(*q));
            b
        })
        .collect();
    let bulk = bulk(&boxes);
    for &s in &bulk.strays {
        warnings.push(format!(
            "#{} {} '{}' lies {:.0} m from the rest of the building: it gets a cell of its own",
            parts[s].id,
            parts[s].class,
            parts[s].name,
            boxes[s].distance(&bulk.bounds)
        ));
    }
    let origin = local_origin(&bulk.bounds);
    let mut model = Model {
        materials: vec![Material::default()],
        origin: origin.to_array(),
        frames: vec![frame],
        ..Model::default()
    };
    let shares = instancing::share(
        &parts
            .iter()
            .map(|p| Shape {
                occurrence: p.occurrence.as_ref(),
                positions: &p.positions,
                indices: &p.indices,
                colours: &p.colours,
            })
            .collect::<Vec<_>>(),
        &kernel_to_model,
    );
    let to_local = DMat4::from_translation(-origin);
    let from_local = DMat4::from_translation(origin);
    let mut def_of = vec![0u32; parts.len()];
    for (k, (p, share)) in parts.into_iter().zip(shares).enumerate() {
        let label = if p.name.is_empty() {
            format!("{} #{}", p.class, p.id)
        } else {
            p.name.clone()
        };
        let (def, transform) = match share {
            Share::Copy { of, moved } => (def_of[of], (to_local * moved * from_local).as_mat4()),
            Share::Own => {
                let positions: Vec<[f32; 3]> = p
                    .positions
                    .iter()
                    .map(|q| (*q - origin).as_vec3().to_array())
                    .collect();
                let lod = mesh_from_streams(&positions, Some(&p.normals), &p.colours, p.indices)
                    .map_err(|e| format!("#{} {} '{}': {e}", p.id, p.class, p.name))?;
                model.defs.push(ObjectDef {
                    name: label.clone(),
                    lods: vec![lod],
                    material: 0,
                });
                (model.defs.len() as u32 - 1, Mat4::IDENTITY)
            }
        };
        def_of[k] = def;
        let mut tags = BTreeMap::new();
        tags.insert("ifc_class".to_string(), p.class.clone());
        tags.insert("guid".to_string(), p.guid);
        if !p.name.is_empty() {
            tags.insert("name".to_string(), p.name);
        }
        if let Some(s) = rel.storey_name(p.id) {
            tags.insert("storey".to_string(), s);
        }
        model.instances.push(Instance {
            name: label,
            def,
            transform,
            material: 0,
            occluder: OCCLUDER_CLASSES.contains(&p.class.to_ascii_uppercase().as_str()),
            tags,
        });
    }
    let kernel_y_up = UpAxis::Z.to_y_up();
    let space_frame = kernel_to_model * kernel_y_up.inverse();
    for id in spaces {
        match space_box(id, &router, &mut decoder) {
            Ok(Some((name, b))) => {
                // Moved in f64, before survey coordinates are narrowed.
                let moved = to_local * space_frame;
                let mut local = Aabb::EMPTY;
                for corner in [b.min, b.max] {
                    local.include(moved.transform_point3(corner).as_vec3());
                }
                model.spaces.push(Space {
                    name,
                    storey: rel.storey_name(id),
                    bounds: local,
                });
            }
            Ok(None) => {}
            Err(e) => warnings.push(format!("space #{id} did not mesh: {e}")),
        }
    }
    model.warnings = warnings;
    Ok(model)
}

/// IFC's Z-up to Portico's Y-up.
fn y_up(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, z, -y)
}

/// Settles the file's frame: its declared unit (`unit_scale` metres per unit, applied by the
/// kernel) and Z up, unless the user gave others; a model whose geometry clearly says
/// otherwise gets a warning. Moves the parts (meshed in metres of the declared unit and turned
/// Y up) to the frame settled, and returns it with the change from the kernel's frame (Z up,
/// declared metres) to the model's.
fn settle_frame(
    parts: &mut [Part],
    unit_scale: f64,
    options: &FrameOptions,
    warnings: &mut Vec<String>,
) -> (SourceFrame, DMat4) {
    let declared = LengthUnit::of_metres(unit_scale);
    let file = SourceFrame {
        unit: declared.unwrap_or(LengthUnit::Metre),
        unit_source: FrameSource::Format,
        unit_why: match declared {
            Some(_) => "the file's IfcUnitAssignment".into(),
            None => format!("the file's IfcUnitAssignment: {unit_scale} m, read as such"),
        },
        up: UpAxis::Z,
        up_source: FrameSource::Format,
        up_why: "IFC".into(),
    };
    // The geometry in the file's own numbers, for the evidence.
    let to_file = (UpAxis::Z.to_y_up() * DMat4::from_scale(DVec3::splat(unit_scale))).inverse();
    let stride = parts.len().div_ceil(super::frame::MAX_SAMPLED).max(1);
    let pieces: Vec<Piece> = parts
        .iter()
        .step_by(stride)
        .flat_map(|p| pieces_of(&p.positions, &p.indices, &to_file))
        .collect();
    let (frame, said) = settle(&pieces, &file, false, options);
    warnings.extend(said);
    let kernel_y_up = UpAxis::Z.to_y_up();
    if options
        .units
        .is_none_or(|u| u == file.unit && declared.is_some())
        && frame.up == file.up
    {
        return (frame, kernel_y_up);
    }
    // From the kernel's frame (declared metres, Z up) to the model's: the unit given over the
    // declared one (without one, the kernel's metres stand: a declared unit this crate has no
    // name for, yards say, keeps its true size), then the up axis given.
    let rescale = options.units.map_or(1.0, |u| u.metres() / unit_scale);
    let kernel_to_model = frame.up.to_y_up() * DMat4::from_scale(DVec3::splat(rescale));
    let fix = kernel_to_model * kernel_y_up.inverse();
    let turn = fix.to_scale_rotation_translation().1;
    for p in parts.iter_mut() {
        p.positions
            .iter_mut()
            .for_each(|q| *q = fix.transform_point3(*q));
        p.normals
            .iter_mut()
            .for_each(|n| *n = (turn * Vec3::from(*n).as_dvec3()).as_vec3().to_array());
    }
    (frame, kernel_to_model)
}

/// Meshes one product (openings subtracted) into a [`Part`]; `None` when it has no triangles.
fn mesh_product(
    id: u32,
    ty: &str,
    router: &GeometryRouter,
    decoder: &mut EntityDecoder,
    rel: &Relations,
) -> Result<Option<Part>, String> {
    let e = decoder.decode_by_id(id).map_err(|e| e.to_string())?;
    let class = e.ifc_type.name().to_string();
    let guid = e.get_string(0).unwrap_or_default().to_string();
    let name = e.get_string(2).unwrap_or_default().trim().to_string();
    let mut subs = router
        .process_element_with_submeshes_and_voids(&e, decoder, &rel.voids)
        .map_err(|e| e.to_string())?;
    if subs.is_empty() {
        // Products without styled items come back as one mesh, not as items.
        let m = router
            .process_element_with_voids(&e, decoder, &rel.voids)
            .map_err(|e| e.to_string())?;
        subs.add(0, m);
    }
    let fallback = rel
        .material_of
        .get(&id)
        .and_then(|m| rel.material_colour.get(m))
        .copied()
        .unwrap_or_else(|| class_colour(ty));
    let mut part = Part {
        id,
        class,
        name,
        guid,
        positions: Vec::new(),
        normals: Vec::new(),
        colours: Vec::new(),
        indices: Vec::new(),
        occurrence: None,
    };
    let mut shapes = Vec::new();
    let mut placement = None;
    for sub in subs.iter() {
        let m = &sub.mesh;
        match m.instance_meta.as_ref().filter(|meta| meta.instanceable) {
            Some(meta) => {
                shapes.push(meta.rep_identity);
                placement.get_or_insert_with(|| placement_of(meta));
            }
            None => shapes.push(0),
        }
        let colour = rel
            .item_colour
            .get(&sub.geometry_id)
            .or_else(|| rel.material_colour.get(&sub.geometry_id))
            .copied()
            .unwrap_or(fallback);
        let colour = linear(colour);
        let base = part.positions.len() as u32;
        part.positions.extend(world_positions(m));
        let count = m.positions.len() / 3;
        if m.normals.len() == m.positions.len() {
            for n in m.normals.chunks_exact(3) {
                part.normals.push([n[0], n[2], -n[1]]);
            }
        } else {
            part.normals.extend(std::iter::repeat_n([0.0; 3], count));
        }
        part.colours.extend(std::iter::repeat_n(colour, count));
        part.indices.extend(m.indices.iter().map(|i| base + i));
    }
    if part
        .positions
        .iter()
        .any(|p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE)
    {
        return Err(format!(
            "a vertex is not a finite number or lies beyond ±{MAX_COORDINATE:.0e} m"
        ));
    }
    if !shapes.contains(&0)
        && let Some(placement) = placement
    {
        part.occurrence = Some(Occurrence { shapes, placement });
    }
    Ok((!part.indices.is_empty()).then_some(part))
}

/// The kernel's placement of an instanceable mesh (`transform · local · canonical`, written
/// row-major) as a matrix.
fn placement_of(meta: &ifc_lite_geometry::InstanceMeta) -> DMat4 {
    let m = |a: &[f64; 16]| DMat4::from_cols_array(a).transpose();
    let mut p = m(&meta.transform);
    if let Some(l) = &meta.local_transform {
        p *= m(l);
    }
    if let Some(c) = &meta.canonical_transform {
        p *= m(c);
    }
    p
}

/// A space's name (`LongName`, else `Name`) and its Y-up world box.
fn space_box(
    id: u32,
    router: &GeometryRouter,
    decoder: &mut EntityDecoder,
) -> Result<Option<(String, DBox)>, String> {
    let e = decoder.decode_by_id(id).map_err(|e| e.to_string())?;
    let name = e
        .get_string(7)
        .filter(|s| !s.trim().is_empty())
        .or_else(|| e.get_string(2))
        .unwrap_or_default()
        .trim()
        .to_string();
    let name = if name.is_empty() {
        format!("#{id}")
    } else {
        name
    };
    let m = router
        .process_element(&e, decoder)
        .map_err(|e| e.to_string())?;
    let mut b = DBox::EMPTY;
    world_positions(&m).for_each(|p| b.include(p));
    Ok((!b.is_empty()).then_some((name, b)))
}

/// A kernel mesh's vertices in world space (its origin added, in f64), Y up.
fn world_positions(m: &ifc_lite_geometry::Mesh) -> impl Iterator<Item = DVec3> + '_ {
    let o = m.origin;
    m.positions
        .chunks_exact(3)
        .map(move |p| y_up(o[0] + p[0] as f64, o[1] + p[1] as f64, o[2] + p[2] as f64))
}

/// sRGB (as IFC writes colours) to linear, alpha kept.
fn linear(c: [f32; 4]) -> [f32; 4] {
    let f = |x: f32| {
        if x <= 0.04045 {
            x / 12.92
        } else {
            ((x + 0.055) / 1.055).powf(2.4)
        }
    };
    [f(c[0]), f(c[1]), f(c[2]), c[3]]
}

/// A colour (sRGB) for a product whose file gives none, by class.
fn class_colour(ty: &str) -> [f32; 4] {
    match ty {
        t if t.starts_with("IFCWALL") => [0.85, 0.83, 0.78, 1.0],
        t if t.starts_with("IFCSLAB") || t.starts_with("IFCROOF") => [0.6, 0.58, 0.55, 1.0],
        "IFCDOOR" => [0.55, 0.38, 0.22, 1.0],
        "IFCWINDOW" => [0.6, 0.75, 0.85, 0.4],
        t if t.starts_with("IFCSTAIR") || t.starts_with("IFCRAILING") => [0.5, 0.5, 0.52, 1.0],
        t if t.starts_with("IFCBEAM")
            || t.starts_with("IFCCOLUMN")
            || t.starts_with("IFCMEMBER") =>
        {
            [0.62, 0.48, 0.32, 1.0]
        }
        _ => [0.75, 0.75, 0.75, 1.0],
    }
}
