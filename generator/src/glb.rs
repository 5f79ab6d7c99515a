//! GLB writer: shared meshes, instance nodes with `extras` tags and `MSFT_lod` LOD chains.
//!
//! Funkhouser §3.1.2's object hierarchy (instances referencing shared definitions with several
//! LODs) maps onto standard glTF: a definition's LODs are meshes; each LOD below the finest is
//! held by one LOD node per definition (outside the scene tree, no transform), and every
//! instance node references the finest mesh and lists those nodes, coarser and coarser, in the
//! `MSFT_lod` extension. Vertices are interleaved (position, normal, RGBA8 colour; 28 bytes),
//! indices are `u16` where they fit; every buffer view starts on a 4-byte boundary.

use std::borrow::Cow;

use serde::Serialize;

use crate::GenerateError;
use crate::assemble::{Instance, MeshRef, Scene};
use crate::mesh::MeshData;

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_BYTE: u32 = 5121;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const TRIANGLES: u32 = 4;
const VERTEX_STRIDE: usize = 28;

#[derive(Serialize)]
struct Root<'a> {
    asset: Asset,
    #[serde(rename = "extensionsUsed", skip_serializing_if = "Vec::is_empty")]
    extensions_used: Vec<&'static str>,
    scene: u32,
    scenes: Vec<SceneJson>,
    nodes: Vec<NodeJson<'a>>,
    meshes: Vec<MeshJson>,
    materials: Vec<Material>,
    accessors: Vec<Accessor>,
    #[serde(rename = "bufferViews")]
    buffer_views: Vec<BufferView>,
    buffers: Vec<Buffer>,
}

#[derive(Serialize)]
struct Asset {
    version: &'static str,
    generator: &'static str,
}

#[derive(Serialize)]
struct SceneJson {
    name: &'static str,
    nodes: Vec<usize>,
}

#[derive(Serialize, Default)]
struct NodeJson<'a> {
    #[serde(skip_serializing_if = "Option::is_none")]
    name: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mesh: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    children: Option<Vec<usize>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    translation: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    rotation: Option<[f32; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    extras: Option<Extras>,
    #[serde(skip_serializing_if = "Option::is_none")]
    extensions: Option<NodeExtensions<'a>>,
}

#[derive(Serialize)]
struct Extras {
    #[serde(skip_serializing_if = "Option::is_none")]
    occluder: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    kind: Option<&'static str>,
    #[serde(rename = "type", skip_serializing_if = "Option::is_none")]
    ty: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    room: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    room_id: Option<u32>,
    storey: u32,
}

#[derive(Serialize)]
struct NodeExtensions<'a> {
    #[serde(rename = "MSFT_lod")]
    msft_lod: MsftLod<'a>,
}

#[derive(Serialize)]
struct MsftLod<'a> {
    ids: &'a [usize],
}

#[derive(Serialize)]
struct MeshJson {
    name: String,
    primitives: [Primitive; 1],
}

#[derive(Serialize)]
struct Primitive {
    attributes: Attributes,
    indices: usize,
    material: usize,
    mode: u32,
}

#[derive(Serialize)]
struct Attributes {
    #[serde(rename = "POSITION")]
    position: usize,
    #[serde(rename = "NORMAL")]
    normal: usize,
    #[serde(rename = "COLOR_0")]
    color: usize,
}

#[derive(Serialize)]
struct Material {
    name: &'static str,
    #[serde(rename = "pbrMetallicRoughness")]
    pbr: Pbr,
    /// Both sides drawn: the generator's thin parts (door panels, shelves, signs) are seen
    /// from either side, and nothing here promises a winding.
    #[serde(rename = "doubleSided")]
    double_sided: bool,
}

#[derive(Serialize)]
struct Pbr {
    #[serde(rename = "baseColorFactor")]
    base_color_factor: [f32; 4],
    #[serde(rename = "metallicFactor")]
    metallic_factor: f32,
    #[serde(rename = "roughnessFactor")]
    roughness_factor: f32,
}

#[derive(Serialize)]
struct Accessor {
    #[serde(rename = "bufferView")]
    buffer_view: usize,
    #[serde(rename = "byteOffset")]
    byte_offset: usize,
    #[serde(rename = "componentType")]
    component_type: u32,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    normalized: bool,
    count: usize,
    #[serde(rename = "type")]
    ty: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    min: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    max: Option<[f32; 3]>,
}

#[derive(Serialize)]
struct BufferView {
    buffer: usize,
    #[serde(rename = "byteOffset")]
    byte_offset: usize,
    #[serde(rename = "byteLength")]
    byte_length: usize,
    #[serde(rename = "byteStride", skip_serializing_if = "Option::is_none")]
    byte_stride: Option<usize>,
    target: u32,
}

#[derive(Serialize)]
struct Buffer {
    #[serde(rename = "byteLength")]
    byte_length: usize,
}

/// The binary chunk with its buffer views and accessors.
#[derive(Default)]
struct BinWriter {
    data: Vec<u8>,
    views: Vec<BufferView>,
    accessors: Vec<Accessor>,
}

impl BinWriter {
    fn align(&mut self) {
        while !self.data.len().is_multiple_of(4) {
            self.data.push(0);
        }
    }

    fn view(&mut self, start: usize, stride: Option<usize>, target: u32) -> usize {
        self.views.push(BufferView {
            buffer: 0,
            byte_offset: start,
            byte_length: self.data.len() - start,
            byte_stride: stride,
            target,
        });
        self.views.len() - 1
    }

    fn accessor(
        &mut self,
        view: usize,
        offset: usize,
        component: u32,
        count: usize,
        ty: &'static str,
    ) -> usize {
        self.accessors.push(Accessor {
            buffer_view: view,
            byte_offset: offset,
            component_type: component,
            normalized: component == UNSIGNED_BYTE,
            count,
            ty,
            min: None,
            max: None,
        });
        self.accessors.len() - 1
    }

    /// Writes one mesh's vertices and indices, returning its primitive.
    fn mesh(&mut self, mesh: &MeshData) -> Primitive {
        self.align();
        let start = self.data.len();
        self.data.reserve(mesh.positions.len() * VERTEX_STRIDE);
        for ((p, n), c) in mesh.positions.iter().zip(&mesh.normals).zip(&mesh.colors) {
            for v in p.iter().chain(n) {
                self.data.extend_from_slice(&v.to_le_bytes());
            }
            self.data.extend_from_slice(c);
        }
        let view = self.view(start, Some(VERTEX_STRIDE), ARRAY_BUFFER);
        let count = mesh.positions.len();
        let position = self.accessor(view, 0, FLOAT, count, "VEC3");
        if let Some((min, max)) = mesh.bounds() {
            self.accessors[position].min = Some(min);
            self.accessors[position].max = Some(max);
        }
        let normal = self.accessor(view, 12, FLOAT, count, "VEC3");
        let color = self.accessor(view, 24, UNSIGNED_BYTE, count, "VEC4");
        let start = self.data.len();
        let component = if count <= usize::from(u16::MAX) {
            for &i in &mesh.indices {
                let short = u16::try_from(i).unwrap_or(u16::MAX);
                self.data.extend_from_slice(&short.to_le_bytes());
            }
            UNSIGNED_SHORT
        } else {
            for &i in &mesh.indices {
                self.data.extend_from_slice(&i.to_le_bytes());
            }
            UNSIGNED_INT
        };
        let view = self.view(start, None, ELEMENT_ARRAY_BUFFER);
        let indices = self.accessor(view, 0, component, mesh.indices.len(), "SCALAR");
        self.align();
        Primitive {
            attributes: Attributes {
                position,
                normal,
                color,
            },
            indices,
            material: 0,
            mode: TRIANGLES,
        }
    }
}

/// Mesh indices of every furniture LOD and the LOD node ids of every definition.
struct Layout {
    /// First mesh index of each definition's LODs.
    furniture_mesh: Vec<usize>,
    /// `MSFT_lod` node ids (LODs 1..) of each definition.
    lod_nodes: Vec<Vec<usize>>,
}

/// Serialises `scene` as a GLB file.
pub(crate) fn write(scene: &Scene) -> Result<Vec<u8>, GenerateError> {
    let mut bin = BinWriter::default();
    let mut meshes = Vec::new();
    for (name, mesh) in &scene.structures {
        meshes.push(MeshJson {
            name: name.clone(),
            primitives: [bin.mesh(mesh)],
        });
    }
    let instance_count: usize = scene.storeys.iter().map(Vec::len).sum();
    let mut next_lod_node = instance_count + scene.storeys.len();
    let mut layout = Layout {
        furniture_mesh: Vec::new(),
        lod_nodes: Vec::new(),
    };
    let mut lod_node_json = Vec::new();
    for def in &scene.library.defs {
        layout.furniture_mesh.push(meshes.len());
        let mut ids = Vec::new();
        for (lod, mesh) in def.lods.iter().enumerate() {
            let name = format!("{}.{}.lod{lod}", def.key.ty.name(), def.key.variant);
            if lod > 0 {
                ids.push(next_lod_node);
                next_lod_node += 1;
                lod_node_json.push(NodeJson {
                    name: Some(name.clone()),
                    mesh: Some(meshes.len()),
                    ..NodeJson::default()
                });
            }
            meshes.push(MeshJson {
                name,
                primitives: [bin.mesh(mesh)],
            });
        }
        layout.lod_nodes.push(ids);
    }
    bin.align();
    let nodes = nodes(scene, &layout, lod_node_json);
    let root = Root {
        asset: Asset {
            version: "2.0",
            generator: "portico-generator",
        },
        extensions_used: if layout.lod_nodes.iter().any(|l| !l.is_empty()) {
            vec!["MSFT_lod"]
        } else {
            Vec::new()
        },
        scene: 0,
        scenes: vec![SceneJson {
            name: "building",
            nodes: (instance_count..instance_count + scene.storeys.len()).collect(),
        }],
        nodes,
        meshes,
        materials: vec![Material {
            name: "vertex-colour",
            pbr: Pbr {
                base_color_factor: [1.0; 4],
                metallic_factor: 0.0,
                roughness_factor: 0.9,
            },
            double_sided: true,
        }],
        accessors: std::mem::take(&mut bin.accessors),
        buffer_views: std::mem::take(&mut bin.views),
        buffers: vec![Buffer {
            byte_length: bin.data.len(),
        }],
    };
    let json = serde_json::to_vec(&root)?;
    let total = 12 + 8 + json.len() as u64 + 3 + 8 + bin.data.len() as u64;
    if total > u64::from(u32::MAX) {
        return Err(GenerateError::TooLarge(total));
    }
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: u32::try_from(total).unwrap_or(u32::MAX),
        },
        json: Cow::Owned(json),
        bin: Some(Cow::Owned(bin.data)),
    };
    Ok(glb.to_vec()?)
}

/// All nodes: instances (storey by storey), then one group node per storey, then LOD nodes.
fn nodes<'a>(scene: &Scene, layout: &'a Layout, lod_nodes: Vec<NodeJson<'a>>) -> Vec<NodeJson<'a>> {
    let mut nodes = Vec::new();
    let mut groups = Vec::new();
    for (s, instances) in scene.storeys.iter().enumerate() {
        let first = nodes.len();
        for inst in instances {
            nodes.push(instance_node(scene, layout, inst, nodes.len()));
        }
        groups.push(NodeJson {
            name: Some(format!("storey {s}")),
            children: Some((first..nodes.len()).collect()),
            extras: Some(Extras {
                occluder: None,
                kind: None,
                ty: None,
                room: None,
                room_id: None,
                storey: s as u32,
            }),
            ..NodeJson::default()
        });
    }
    nodes.extend(groups);
    nodes.extend(lod_nodes);
    nodes
}

fn instance_node<'a>(
    scene: &Scene,
    layout: &'a Layout,
    inst: &Instance,
    index: usize,
) -> NodeJson<'a> {
    let (mesh, lods, label) = match inst.mesh {
        MeshRef::Structure(i) => (i, None, inst.tags.kind),
        MeshRef::Furniture(d) => {
            let ids = &layout.lod_nodes[d];
            let ext = (!ids.is_empty()).then_some(NodeExtensions {
                msft_lod: MsftLod { ids },
            });
            (
                layout.furniture_mesh[d],
                ext,
                scene.library.defs[d].key.ty.name(),
            )
        }
    };
    let tags = inst.tags;
    NodeJson {
        name: Some(format!("{label}#{index}")),
        mesh: Some(mesh),
        translation: Some(inst.translation),
        rotation: (inst.rotation != [0.0, 0.0, 0.0, 1.0]).then_some(inst.rotation),
        extras: Some(Extras {
            occluder: Some(tags.occluder),
            kind: Some(tags.kind),
            ty: tags.ty,
            room: tags.room.map(|r| r.0.name()),
            room_id: tags.room.map(|r| r.1),
            storey: tags.storey,
        }),
        extensions: lods,
        ..NodeJson::default()
    }
}

/// The same GLB without any node's `extras`: the building as a modelling tool without
/// Portico's tags would export it (no `occluder`, `kind`, `room` or `storey`), for measuring
/// how well the cells are found from the geometry alone.
pub fn without_tags(glb: &[u8]) -> Result<Vec<u8>, GenerateError> {
    let parsed = gltf::binary::Glb::from_slice(glb)?;
    let mut root: serde_json::Value = serde_json::from_slice(&parsed.json)?;
    if let Some(nodes) = root.get_mut("nodes").and_then(|n| n.as_array_mut()) {
        for n in nodes {
            if let Some(o) = n.as_object_mut() {
                o.remove("extras");
            }
        }
    }
    let out = gltf::binary::Glb {
        header: parsed.header,
        json: Cow::Owned(serde_json::to_vec(&root)?),
        bin: parsed.bin,
    };
    Ok(out.to_vec()?)
}
