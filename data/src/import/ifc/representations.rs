//! Which of a product's shape representations are drawn.
//!
//! An IFC product may carry several representations, told apart by their identifier
//! (IFC 4.3 §8.18.3.14, `IfcShapeRepresentation`): `Body` is the shape, while `Clearance` (a
//! door's swing space), `Box`, `Axis`, `FootPrint`, `Reference`, `Lighting`, `CoG` and others
//! describe it. The geometry kernel meshes every representation whose *type* is a solid, so a
//! door's clearance volume was drawn as a block in front of its doorway. Here each product's
//! `IfcProductDefinitionShape` is cut down, in the file's text before the kernel reads it, to
//! the representations that are drawn: `Body` (and unnamed ones, which the kernel judges by
//! type) where there are any; else `Body-FallBack` or `Facetation`; else other names the
//! standard does not list; else `Box`. Representations that describe rather than show
//! (`Clearance`, `Axis`, `FootPrint`, ...) are never drawn. Opening elements keep theirs: their
//! shapes are the holes cut into walls.

use ifc_lite_core::{EntityDecoder, EntityScanner};
use rustc_hash::{FxHashMap, FxHashSet};
use std::borrow::Cow;

/// Representation identifiers that describe a product rather than show it.
const NEVER: [&str; 11] = [
    "CLEARANCE",
    "AXIS",
    "FOOTPRINT",
    "REFERENCE",
    "LIGHTING",
    "COG",
    "PROFILE",
    "SURVEYPOINTS",
    "ANNOTATION",
    "OUTLINE",
    "CONTOUR",
];

/// Classes whose shapes are used as they are (holes and what cuts them, rooms).
const AS_THEY_ARE: [&str; 5] = [
    "IFCOPENINGELEMENT",
    "IFCOPENINGSTANDARDCASE",
    "IFCVOIDINGFEATURE",
    "IFCEARTHWORKSCUT",
    "IFCSPACE",
];

/// How much a representation identifier is wanted: 0 best; `None` never drawn.
fn rank(identifier: Option<&str>) -> Option<u8> {
    let id = identifier.map(|s| s.trim().to_ascii_uppercase());
    match id.as_deref() {
        None | Some("") | Some("BODY") => Some(0),
        Some("BODY-FALLBACK") | Some("FACETATION") => Some(1),
        Some("BOX") => Some(3),
        Some(other) if NEVER.contains(&other) => None,
        Some(_) => Some(2),
    }
}

/// The file with every product's representations cut down to the drawn ones, how many
/// representations were left out, and the product definition shapes left with nothing to
/// draw (their products are not reported as lacking a shape).
pub struct BodyOnly<'a> {
    /// The text to mesh from (borrowed when nothing changed).
    pub content: Cow<'a, str>,
    /// Representations left out (clearances, axes, boxes beside a body, ...).
    pub left_out: usize,
    /// Products with nothing to draw: no shape at all, or only representations that describe
    /// it (a clearance, an axis, a footprint).
    pub shapeless: FxHashSet<u32>,
}

/// Cuts each product's representations down to the drawn ones (see the module documentation).
pub fn body_only(content: &str) -> BodyOnly<'_> {
    let mut decoder = EntityDecoder::new(content);
    let mut scanner = EntityScanner::new(content);
    let mut identifier: FxHashMap<u32, Option<String>> = FxHashMap::default();
    let mut shapes: Vec<(u32, usize, usize)> = Vec::new();
    let mut products: Vec<(u32, String)> = Vec::new();
    while let Some((id, ty, start, end)) = scanner.next_entity() {
        let ty = ty.to_ascii_uppercase();
        match ty.as_str() {
            "IFCSHAPEREPRESENTATION" | "IFCTOPOLOGYREPRESENTATION" => {
                if let Ok(e) = decoder.decode_by_id(id) {
                    identifier.insert(id, e.get_string(1).map(str::to_string));
                }
            }
            "IFCPRODUCTDEFINITIONSHAPE" => shapes.push((id, start, end)),
            _ if ifc_lite_core::has_geometry_by_name(&ty) => products.push((id, ty)),
            _ => {}
        }
    }
    // Shapes of holes and rooms stay whole; the products of every shape, to name the
    // shapeless ones.
    let mut whole = FxHashSet::default();
    let mut users: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
    let mut shapeless = FxHashSet::default();
    for (id, ty) in &products {
        let Ok(e) = decoder.decode_by_id(*id) else {
            continue;
        };
        let Some(shape) = e.get_ref(6) else {
            shapeless.insert(*id);
            continue;
        };
        if AS_THEY_ARE.contains(&ty.as_str()) {
            whole.insert(shape);
        }
        users.entry(shape).or_default().push(*id);
    }
    let mut edits: Vec<(usize, usize, String)> = Vec::new();
    let mut left_out = 0;
    for &(id, start, end) in &shapes {
        if whole.contains(&id) {
            continue;
        }
        let Some(reps) = decoder.decode_by_id(id).ok().and_then(|e| e.get_refs(2)) else {
            continue;
        };
        let ranks: Vec<Option<u8>> = reps
            .iter()
            .map(|r| match identifier.get(r) {
                Some(name) => rank(name.as_deref()),
                None => Some(0),
            })
            .collect();
        let best = ranks.iter().flatten().min().copied();
        let kept: Vec<u32> = reps
            .iter()
            .zip(&ranks)
            .filter(|(_, r)| r.is_some() && *r == &best)
            .map(|(r, _)| *r)
            .collect();
        if kept.len() == reps.len() {
            continue;
        }
        let Some((from, to)) = list_span(&content[start..end]) else {
            continue;
        };
        left_out += reps.len() - kept.len();
        if kept.is_empty() {
            shapeless.extend(users.get(&id).into_iter().flatten());
        }
        let list = kept
            .iter()
            .map(|r| format!("#{r}"))
            .collect::<Vec<_>>()
            .join(",");
        edits.push((start + from, start + to, list));
    }
    if edits.is_empty() {
        return BodyOnly {
            content: Cow::Borrowed(content),
            left_out,
            shapeless,
        };
    }
    edits.sort_by_key(|e| e.0);
    let mut out = String::with_capacity(content.len());
    let mut at = 0;
    for (from, to, list) in edits {
        out.push_str(&content[at..from]);
        out.push_str(&list);
        at = to;
    }
    out.push_str(&content[at..]);
    BodyOnly {
        content: Cow::Owned(out),
        left_out,
        shapeless,
    }
}

/// Where the inside of the last attribute's list lies in an entity's text
/// (`#9=IFCPRODUCTDEFINITIONSHAPE($,$,(#5,#7));` → the span of `#5,#7`), if its last
/// attribute is a list of references.
fn list_span(text: &str) -> Option<(usize, usize)> {
    let b = text.as_bytes();
    let entity_close = text.rfind(')')?;
    let list_close = text[..entity_close].trim_end().len().checked_sub(1)?;
    if b[list_close] != b')' {
        return None;
    }
    let list_open = text[..list_close].rfind('(')?;
    let inside = &text[list_open + 1..list_close];
    inside
        .chars()
        .all(|c| c == '#' || c == ',' || c.is_ascii_digit() || c.is_whitespace())
        .then_some((list_open + 1, list_close))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn body_is_drawn_and_clearance_never() {
        assert_eq!(rank(Some("Body")), Some(0));
        assert_eq!(rank(None), Some(0));
        assert_eq!(rank(Some("Facetation")), Some(1));
        assert_eq!(rank(Some("Box")), Some(3));
        assert_eq!(rank(Some("Clearance")), None);
        assert_eq!(rank(Some("FootPrint")), None);
    }

    #[test]
    fn the_list_is_found_after_names_with_brackets() {
        let t = "#9=IFCPRODUCTDEFINITIONSHAPE('a (b), c',$,(#5, #7));";
        let (a, b) = list_span(t).unwrap();
        assert_eq!(&t[a..b], "#5, #7");
        assert_eq!(list_span("#9=IFCPRODUCTDEFINITIONSHAPE($,$,$);"), None);
    }
}
