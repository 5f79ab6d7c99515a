//! What an IFC file says about its products besides their shapes: the openings cut into each
//! host (`IfcRelVoidsElement`), the storey each product stands on
//! (`IfcRelContainedInSpatialStructure`, `IfcRelAggregates`), and the colours of its
//! representation items and materials (`IfcStyledItem`, `IfcMaterialDefinitionRepresentation`,
//! `IfcRelAssociatesMaterial`). One pass over the file's entities collects all of it.

use ifc_lite_core::{AttributeValue, EntityDecoder, EntityScanner, IfcType};
use rustc_hash::FxHashMap;

/// A building storey: its name and elevation (metres above the project's zero, as written).
#[derive(Debug, Clone, PartialEq)]
pub struct Storey {
    /// `IfcBuildingStorey.Name`, or `#id` when it has none.
    pub name: String,
    /// `IfcBuildingStorey.Elevation` in the file's length unit (0 when missing).
    pub elevation: f64,
}

/// The relations the importer needs, keyed by STEP entity id.
#[derive(Debug, Default)]
pub struct Relations {
    /// Host element → the opening elements cut into it.
    pub voids: FxHashMap<u32, Vec<u32>>,
    /// Product or space → the storey that contains or aggregates it.
    pub storey_of: FxHashMap<u32, u32>,
    /// Storeys by id.
    pub storeys: FxHashMap<u32, Storey>,
    /// Representation item → sRGB colour with alpha (`1 − Transparency`).
    pub item_colour: FxHashMap<u32, [f32; 4]>,
    /// Material → sRGB colour with alpha.
    pub material_colour: FxHashMap<u32, [f32; 4]>,
    /// Product → its material (or the first layer's material of a layer set).
    pub material_of: FxHashMap<u32, u32>,
    /// Products made of parts (`IfcRelAggregates`: an `IfcElementAssembly`, a roof of slabs,
    /// a stair of flights): their parts carry the shape. (`IfcRelNests` is not read: IFC4 nests
    /// shapeless ports under every duct and pipe, which carry no shape of their host.)
    pub wholes: rustc_hash::FxHashSet<u32>,
}

impl Relations {
    /// The name of the storey a product or space is on, if the file says.
    pub fn storey_name(&self, id: u32) -> Option<String> {
        let storey = self.storey_of.get(&id)?;
        self.storeys.get(storey).map(|s| s.name.clone())
    }
}

/// Scans the whole file once and resolves the relations above.
pub fn scan(content: &str) -> Relations {
    let mut rel = Relations::default();
    let mut decoder = EntityDecoder::new(content);
    let mut scanner = EntityScanner::new(content);
    let mut contained: Vec<(u32, Vec<u32>)> = Vec::new();
    let mut material_reps: Vec<(u32, Vec<u32>)> = Vec::new();
    let mut associations: Vec<(u32, Vec<u32>)> = Vec::new();
    let mut memo = StyleMemo::default();
    while let Some((id, ty, start, end)) = scanner.next_entity() {
        // STEP keywords are case-insensitive.
        let ty = ty.to_ascii_uppercase();
        let wanted = matches!(
            ty.as_str(),
            "IFCRELVOIDSELEMENT"
                | "IFCRELCONTAINEDINSPATIALSTRUCTURE"
                | "IFCRELAGGREGATES"
                | "IFCBUILDINGSTOREY"
                | "IFCSTYLEDITEM"
                | "IFCMATERIALDEFINITIONREPRESENTATION"
                | "IFCRELASSOCIATESMATERIAL"
        );
        if !wanted {
            continue;
        }
        let Ok(e) = decoder.decode_at_with_id(id, start, end) else {
            continue;
        };
        match ty.as_str() {
            "IFCRELVOIDSELEMENT" => {
                if let (Some(host), Some(opening)) = (e.get_ref(4), e.get_ref(5)) {
                    rel.voids.entry(host).or_default().push(opening);
                }
            }
            "IFCRELCONTAINEDINSPATIALSTRUCTURE" => {
                if let (Some(elements), Some(structure)) = (e.get_refs(4), e.get_ref(5)) {
                    contained.push((structure, elements));
                }
            }
            "IFCRELAGGREGATES" => {
                if let (Some(whole), Some(parts)) = (e.get_ref(4), e.get_refs(5)) {
                    rel.wholes.insert(whole);
                    contained.push((whole, parts));
                }
            }
            "IFCBUILDINGSTOREY" => {
                let name = e
                    .get_string(2)
                    .filter(|s| !s.is_empty())
                    .map_or_else(|| format!("#{id}"), str::to_string);
                let elevation = e.get_float(9).unwrap_or(0.0);
                rel.storeys.insert(id, Storey { name, elevation });
            }
            "IFCSTYLEDITEM" => {
                if let (Some(item), Some(styles)) = (e.get_ref(0), e.get(1))
                    && let Some(c) = colour_of_styles(styles, &mut decoder, &mut memo)
                {
                    rel.item_colour.entry(item).or_insert(c);
                }
            }
            "IFCMATERIALDEFINITIONREPRESENTATION" => {
                if let (Some(reps), Some(material)) = (e.get_refs(2), e.get_ref(3)) {
                    material_reps.push((material, reps));
                }
            }
            "IFCRELASSOCIATESMATERIAL" => {
                if let (Some(objects), Some(material)) = (e.get_refs(4), e.get_ref(5)) {
                    associations.push((material, objects));
                }
            }
            _ => {}
        }
    }
    // Storeys contain products directly, and spaces (and the parts of aggregates such as
    // stairs) through aggregation: follow the chains down from each storey.
    let mut children: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
    for (parent, kids) in contained {
        children.entry(parent).or_default().extend(kids);
    }
    let storey_ids: Vec<u32> = rel.storeys.keys().copied().collect();
    for storey in storey_ids {
        let mut stack = vec![storey];
        while let Some(p) = stack.pop() {
            for &k in children.get(&p).into_iter().flatten() {
                if k != storey && !rel.storeys.contains_key(&k) && !rel.storey_of.contains_key(&k) {
                    rel.storey_of.insert(k, storey);
                    stack.push(k);
                }
            }
        }
    }
    for (material, reps) in material_reps {
        let colour = reps.iter().find_map(|&r| {
            let rep = decoder.decode_by_id(r).ok()?;
            rep.get_refs(3)?
                .into_iter()
                .take(MAX_STYLES)
                .find_map(|styled| {
                    let s = decoder.decode_by_id(styled).ok()?;
                    colour_of_styles(s.get(1)?, &mut decoder, &mut memo)
                })
        });
        if let Some(c) = colour {
            rel.material_colour.insert(material, c);
        }
    }
    for (material, objects) in associations {
        let Some(m) = first_material(material, &mut decoder) else {
            continue;
        };
        for o in objects {
            rel.material_of.entry(o).or_insert(m);
        }
    }
    rel
}

/// The `IfcMaterial` behind a material select: itself, or the first layer's of a layer set
/// (usage), or the first of a list.
fn first_material(id: u32, decoder: &mut EntityDecoder) -> Option<u32> {
    let mut id = id;
    for _ in 0..4 {
        let e = decoder.decode_by_id(id).ok()?;
        id = match e.ifc_type {
            IfcType::IfcMaterial => return Some(id),
            IfcType::IfcMaterialLayerSetUsage => e.get_ref(0)?,
            IfcType::IfcMaterialLayerSet | IfcType::IfcMaterialList => {
                e.get_refs(0)?.into_iter().next()?
            }
            IfcType::IfcMaterialLayer => e.get_ref(0)?,
            _ => return None,
        };
    }
    None
}

/// Styles looked at per list, and how deep style assignments are followed: a hostile file
/// cannot make the lookup explode.
const MAX_STYLES: usize = 16;
/// See [`MAX_STYLES`].
const MAX_DEPTH: u32 = 3;

/// Colours already resolved, by style id (`None`: the style has none, or is being resolved).
type StyleMemo = FxHashMap<u32, Option<[f32; 4]>>;

/// The first surface colour in a list of presentation styles (or style assignments).
fn colour_of_styles(
    styles: &AttributeValue,
    decoder: &mut EntityDecoder,
    memo: &mut StyleMemo,
) -> Option<[f32; 4]> {
    let ids: Vec<u32> = match styles.as_list() {
        Some(list) => list
            .iter()
            .filter_map(AttributeValue::as_entity_ref)
            .take(MAX_STYLES)
            .collect(),
        None => styles.as_entity_ref().into_iter().collect(),
    };
    ids.into_iter()
        .find_map(|id| colour_of_style(id, decoder, memo, 0))
}

/// A style's colour: an `IfcSurfaceStyle`'s rendering or shading colour, looked for through
/// style assignments (IFC 2x3) at most [`MAX_DEPTH`] levels deep, each style once.
fn colour_of_style(
    id: u32,
    decoder: &mut EntityDecoder,
    memo: &mut StyleMemo,
    depth: u32,
) -> Option<[f32; 4]> {
    if let Some(known) = memo.get(&id) {
        return *known;
    }
    // Marked before looking, so a style that lists itself ends the search.
    memo.insert(id, None);
    let found = resolve_style(id, decoder, memo, depth);
    memo.insert(id, found);
    found
}

/// [`colour_of_style`] without the memo.
fn resolve_style(
    id: u32,
    decoder: &mut EntityDecoder,
    memo: &mut StyleMemo,
    depth: u32,
) -> Option<[f32; 4]> {
    if depth > MAX_DEPTH {
        return None;
    }
    let style = decoder.decode_by_id(id).ok()?;
    match style.ifc_type {
        IfcType::IfcSurfaceStyle => style
            .get_refs(2)?
            .into_iter()
            .take(MAX_STYLES)
            .find_map(|r| {
                let shading = decoder.decode_by_id(r).ok()?;
                if !matches!(
                    shading.ifc_type,
                    IfcType::IfcSurfaceStyleRendering | IfcType::IfcSurfaceStyleShading
                ) {
                    return None;
                }
                let rgb = decoder.decode_by_id(shading.get_ref(0)?).ok()?;
                let c = [1, 2, 3].map(|k| rgb.get_float(k).unwrap_or(0.8).clamp(0.0, 1.0) as f32);
                let alpha = 1.0 - shading.get_float(1).unwrap_or(0.0).clamp(0.0, 1.0) as f32;
                Some([c[0], c[1], c[2], alpha])
            }),
        _ => style
            .get_refs(0)?
            .into_iter()
            .take(MAX_STYLES)
            .find_map(|r| colour_of_style(r, decoder, memo, depth + 1)),
    }
}
