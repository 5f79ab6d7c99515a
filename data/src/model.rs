//! The in-memory model that importers produce and the builder consumes: object definitions
//! with one or more LODs, shared by instances (Funkhouser §3.1, Fig. 3.4–3.5).

use crate::geometry::{Aabb, Mesh};
use crate::texture::{AlphaMode, TextureImage};
use glam::Mat4;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A surface material: its colour (already multiplied into the vertex colours by the
/// importers), its texture and what the texture colours, the light it gives off, how its alpha
/// is used and which of its sides are drawn (glTF 2.0 §3.9; MTL's `Kd`, `Ke`, `d`/`Tr`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Name from the source file.
    pub name: String,
    /// Linear RGBA base colour. The importers multiply it into the vertex colours, so draws do
    /// not apply it again; build-time stand-ins without vertices (cluster colour boxes drawn
    /// without a painter) use it.
    pub base_color: [f32; 4],
    /// The material's texture: an index into [`Model::textures`] (in a database, into
    /// [`crate::format::Header::textures`]); [`Material::texture_role`] says what it colours.
    pub texture: Option<u32>,
    /// What the texture multiplies: the base colour (as glTF's `baseColorTexture`), the
    /// emissive colour (`emissiveTexture`: baked lighting), or both (one image in both slots).
    pub texture_role: TextureRole,
    /// Light the surface gives off, added to the shaded colour (linear RGB: glTF's
    /// `emissiveFactor` × `KHR_materials_emissive_strength`, MTL's `Ke`); black for none.
    pub emissive: [f32; 3],
    /// Drawn without lighting: the colour as it is (glTF's `KHR_materials_unlit`; baked scans).
    pub unlit: bool,
    /// Both sides drawn (and lit). `false` (glTF's default, `doubleSided: false`) culls the
    /// faces seen from behind, so a coincident reversed copy (SketchUp's back faces) never
    /// shows through. OBJ and IFC say nothing of sides: their materials are two-sided.
    pub double_sided: bool,
    /// How alpha is used (opaque, cut out, blended).
    pub alpha: AlphaMode,
}

/// What a material's texture colours ([`Material::texture_role`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum TextureRole {
    /// The base colour (lit).
    #[default]
    Base,
    /// The emissive colour (added after lighting).
    Emissive,
    /// Both: the same image is the base colour and the emissive colour.
    Both,
}

impl TextureRole {
    /// Whether the texture multiplies the base colour.
    pub fn base(self) -> bool {
        self != TextureRole::Emissive
    }

    /// Whether the texture multiplies the emissive colour.
    pub fn emissive(self) -> bool {
        self != TextureRole::Base
    }
}

/// What a renderer needs of a material beside its colour, texture and alpha: what the texture
/// colours, the light given off, whether it is lit and which sides are drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    /// [`Material::texture_role`].
    pub texture_role: TextureRole,
    /// [`Material::emissive`] (linear RGB).
    pub emissive: [f32; 3],
    /// [`Material::unlit`].
    pub unlit: bool,
    /// [`Material::double_sided`].
    pub double_sided: bool,
}

impl Default for Surface {
    /// A lit, two-sided surface whose texture is its base colour, giving off no light.
    fn default() -> Self {
        Material::default().surface()
    }
}

impl Material {
    /// The material's [`Surface`].
    pub fn surface(&self) -> Surface {
        Surface {
            texture_role: self.texture_role,
            emissive: self.emissive,
            unlit: self.unlit,
            double_sided: self.double_sided,
        }
    }
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            base_color: [1.0; 4],
            texture: None,
            texture_role: TextureRole::Base,
            emissive: [0.0; 3],
            unlit: false,
            double_sided: true,
            alpha: AlphaMode::Opaque,
        }
    }
}

/// An object definition: its LODs, finest first, in the definition's own coordinates.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObjectDef {
    /// Name from the source file (mesh or object name).
    pub name: String,
    /// LOD meshes, finest first. Importers give one (or the source's own LODs); the builder adds
    /// coarser ones.
    pub lods: Vec<Mesh>,
    /// Default material index.
    pub material: u32,
}

/// A placed copy of a definition.
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    /// Node name from the source file.
    pub name: String,
    /// Index into [`Model::defs`].
    pub def: u32,
    /// Object-to-world transform.
    pub transform: Mat4,
    /// Material index (overrides the definition's when it differs).
    pub material: u32,
    /// Whether this is a structural occluder (wall, floor, ceiling), from the source's `extras`.
    pub occluder: bool,
    /// Every other scalar tag from the source's `extras` (kind, room, storey, ...).
    pub tags: BTreeMap<String, String>,
}

/// A room the source names (an IFC `IfcSpace`): the cell subdivision splits along its box, so
/// that cells follow the building's own rooms.
#[derive(Debug, Clone, PartialEq)]
pub struct Space {
    /// The room's name (`LongName`, else `Name`).
    pub name: String,
    /// The storey it is on, when the source says.
    pub storey: Option<String>,
    /// Its bounding box, in the model's local coordinates (metres, Y up).
    pub bounds: Aabb,
}

/// A whole imported model.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Model {
    /// Materials; index 0 always exists.
    pub materials: Vec<Material>,
    /// Object definitions.
    pub defs: Vec<ObjectDef>,
    /// Instances of the definitions.
    pub instances: Vec<Instance>,
    /// The files it came from.
    pub sources: Vec<String>,
    /// Each source's unit and up axis, in the order of `sources` (the importers converted the
    /// model from it to metres, Y up).
    pub frames: Vec<crate::frame::SourceFrame>,
    /// World position (metres, double precision) of the model's local origin: every coordinate
    /// in the model is relative to it. Zero unless the source sits far from its own origin
    /// (survey coordinates), see [`crate::bulk::local_origin`].
    pub origin: [f64; 3],
    /// What the importers noticed and worked around (one line each, without the file name).
    pub warnings: Vec<String>,
    /// The rooms the source names (IFC spaces); empty for formats without rooms.
    pub spaces: Vec<Space>,
    /// Decoded base-colour textures the materials refer to.
    pub textures: Vec<TextureImage>,
}

impl Model {
    /// Appends another model, renumbering its materials and definitions and moving its
    /// instances from its origin to this model's (the first model's origin wins).
    pub fn merge(&mut self, other: Model) {
        if self.instances.is_empty() && self.defs.is_empty() {
            self.origin = other.origin;
        }
        let shift = glam::DVec3::from(other.origin) - glam::DVec3::from(self.origin);
        let shift = glam::DMat4::from_translation(shift);
        let mat_base = self.materials.len() as u32;
        let def_base = self.defs.len() as u32;
        let tex_base = self.textures.len() as u32;
        self.textures.extend(other.textures);
        self.materials
            .extend(other.materials.into_iter().map(|mut m| {
                m.texture = m.texture.map(|t| t + tex_base);
                m
            }));
        self.defs.extend(other.defs.into_iter().map(|mut d| {
            d.material += mat_base;
            d
        }));
        self.instances
            .extend(other.instances.into_iter().map(|mut i| {
                i.def += def_base;
                i.material += mat_base;
                i.transform = (shift * i.transform.as_dmat4()).as_mat4();
                i
            }));
        self.sources.extend(other.sources);
        self.frames.extend(other.frames);
        self.warnings.extend(other.warnings);
        let shift = shift.as_mat4();
        self.spaces.extend(other.spaces.into_iter().map(|mut s| {
            s.bounds = s.bounds.transformed(&shift);
            s
        }));
    }

    /// World-space bounds of every instance's finest LOD.
    pub fn bounds(&self) -> Aabb {
        self.instances.iter().fold(Aabb::EMPTY, |acc, inst| {
            let local = self.defs[inst.def as usize]
                .lods
                .first()
                .map(Mesh::bounds)
                .unwrap_or(Aabb::EMPTY);
            acc.union(&local.transformed(&inst.transform))
        })
    }
}
