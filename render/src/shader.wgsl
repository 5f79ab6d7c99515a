// Portico walkthrough shader (render/src/renderer.rs): per-vertex colour times a per-draw material
// colour (times the texture for textured meshes: vs_textured / fs_textured), lit by one
// directional light plus ambient, plus the light the surface gives off (glTF 2.0 §3.9.3:
// emissive is added after lighting). Lighting is two-sided (|n·l|): most building models are
// two-sided; a single-sided surface (glTF's doubleSided: false) discards the faces seen from
// behind (flags below, as render/src/pipeline.rs sets them).

struct Globals {
    view_proj: mat4x4<f32>,
    // xyz: unit direction towards the light (world space).
    light_dir: vec4<f32>,
    // x: ambient fraction in 0..1.
    ambient: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) color: vec4<f32>,
    // Per-instance object-to-world matrix, column by column.
    @location(3) model_0: vec4<f32>,
    @location(4) model_1: vec4<f32>,
    @location(5) model_2: vec4<f32>,
    @location(6) model_3: vec4<f32>,
    // Per-instance material base colour.
    @location(7) tint: vec4<f32>,
    // x: alpha cutoff; y: 1 when blended; z: surface flags.
    @location(8) params: vec4<f32>,
    // Per-instance emissive colour (rgb).
    @location(10) emissive: vec4<f32>,
};

// Surface flags (params.z): drawn unlit; back faces discarded; the transform mirrors; the
// texture (or the tint, when it is not resident) multiplies the base colour; the emissive one.
const UNLIT: u32 = 1u;
const CULL_BACK: u32 = 2u;
const MIRRORED: u32 = 4u;
const TEXTURE_BASE: u32 = 8u;
const TEXTURE_EMISSIVE: u32 = 16u;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
    @location(2) emissive: vec3<f32>,
    @location(3) @interpolate(flat) flags: u32,
};

fn has(flags: u32, flag: u32) -> bool {
    return (flags & flag) != 0u;
}

// The base colour and the emissive colour a tint multiplies, as the flags say.
fn tinted(color: vec4<f32>, tint: vec4<f32>, flags: u32) -> vec4<f32> {
    return color * select(vec4<f32>(1.0), tint, has(flags, TEXTURE_BASE));
}

fn glow(emissive: vec3<f32>, tint: vec3<f32>, flags: u32) -> vec3<f32> {
    return emissive * select(vec3<f32>(1.0), tint, has(flags, TEXTURE_EMISSIVE));
}

// Whether a fragment on this side is drawn.
fn seen(flags: u32, front: bool) -> bool {
    return !has(flags, CULL_BACK) || (front != has(flags, MIRRORED));
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    let model = mat4x4<f32>(v.model_0, v.model_1, v.model_2, v.model_3);
    let flags = u32(round(v.params.z));
    var out: VertexOut;
    out.clip = globals.view_proj * (model * vec4<f32>(v.position, 1.0));
    // Upper 3x3 of the model matrix: exact for rigid motion plus uniform scale.
    out.normal = mat3x3<f32>(v.model_0.xyz, v.model_1.xyz, v.model_2.xyz) * v.normal.xyz;
    out.color = tinted(v.color, v.tint, flags);
    out.emissive = glow(v.emissive.rgb, v.tint.rgb, flags);
    out.flags = flags;
    return out;
}

// The lit colour: shaded, unless the surface is unlit.
fn lit(rgb: vec3<f32>, normal: vec3<f32>, flags: u32) -> vec3<f32> {
    return select(rgb * shade(normal), rgb, has(flags, UNLIT));
}

fn shade(normal: vec3<f32>) -> f32 {
    let len2 = dot(normal, normal);
    let has_normal = len2 > 1e-12;
    let n = normal * inverseSqrt(select(1.0, len2, has_normal));
    let diffuse = select(1.0, abs(dot(n, globals.light_dir.xyz)), has_normal);
    let ambient = globals.ambient.x;
    return ambient + (1.0 - ambient) * diffuse;
}

// Opaque plain surfaces: a single-sided one is drawn by a pipeline that culls its back faces
// (render/src/material.rs), so nothing here discards and the early depth test stays.
fn plain(in: VertexOut) -> vec4<f32> {
    return vec4<f32>(lit(in.color.rgb, in.normal, in.flags) + in.emissive, in.color.a);
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return plain(in);
}

// Blended plain surfaces: back faces of single-sided ones discarded here.
@fragment
fn fs_over(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    if !seen(in.flags, front) {
        discard;
    }
    return plain(in);
}

// Textured meshes: the texture (group 1) at the mesh's coordinates (location 9),
// mip-mapped; texels under a cut-out material's cutoff (location 8, x; 0 = none) are dropped;
// alpha is written only for blended materials (location 8, y = 1).
@group(1) @binding(0) var base_color: texture_2d<f32>;
@group(1) @binding(1) var base_sampler: sampler;

struct TexturedIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) color: vec4<f32>,
    @location(3) model_0: vec4<f32>,
    @location(4) model_1: vec4<f32>,
    @location(5) model_2: vec4<f32>,
    @location(6) model_3: vec4<f32>,
    @location(7) tint: vec4<f32>,
    @location(8) params: vec4<f32>,
    @location(9) uv: vec2<f32>,
    @location(10) emissive: vec4<f32>,
};

struct TexturedOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) cutoff: f32,
    @location(4) blend: f32,
    @location(5) emissive: vec3<f32>,
    @location(6) @interpolate(flat) flags: u32,
};

@vertex
fn vs_textured(v: TexturedIn) -> TexturedOut {
    let model = mat4x4<f32>(v.model_0, v.model_1, v.model_2, v.model_3);
    var out: TexturedOut;
    out.clip = globals.view_proj * (model * vec4<f32>(v.position, 1.0));
    out.normal = mat3x3<f32>(v.model_0.xyz, v.model_1.xyz, v.model_2.xyz) * v.normal.xyz;
    let flags = u32(round(v.params.z));
    out.color = tinted(v.color, v.tint, flags);
    out.emissive = glow(v.emissive.rgb, v.tint.rgb, flags);
    out.uv = v.uv;
    out.cutoff = v.params.x;
    out.blend = v.params.y;
    out.flags = flags;
    return out;
}

@fragment
fn fs_textured(in: TexturedOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let t = textureSample(base_color, base_sampler, in.uv);
    if !seen(in.flags, front) {
        discard;
    }
    let c = tinted(in.color, t, in.flags);
    if (in.cutoff > 0.0 && c.a < in.cutoff) {
        discard;
    }
    // Alpha counts only for blended materials (glTF: OPAQUE ignores it, MASK is all or nothing).
    let alpha = select(1.0, c.a, in.blend > 0.5);
    return vec4<f32>(lit(c.rgb, in.normal, in.flags) + glow(in.emissive, t.rgb, in.flags), alpha);
}
