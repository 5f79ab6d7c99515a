// Portico walkthrough shader (render/src/renderer.rs): per-vertex colour times a per-draw material
// colour (times the base-colour texture for textured meshes: vs_textured / fs_textured), lit by
// one directional light plus ambient. Lighting is two-sided (|n·l|) because building models are
// drawn without back-face culling.

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
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    let model = mat4x4<f32>(v.model_0, v.model_1, v.model_2, v.model_3);
    var out: VertexOut;
    out.clip = globals.view_proj * (model * vec4<f32>(v.position, 1.0));
    // Upper 3x3 of the model matrix: exact for rigid motion plus uniform scale.
    out.normal = mat3x3<f32>(v.model_0.xyz, v.model_1.xyz, v.model_2.xyz) * v.normal.xyz;
    out.color = v.color * v.tint;
    return out;
}

fn shade(normal: vec3<f32>) -> f32 {
    let len2 = dot(normal, normal);
    let has_normal = len2 > 1e-12;
    let n = normal * inverseSqrt(select(1.0, len2, has_normal));
    let diffuse = select(1.0, abs(dot(n, globals.light_dir.xyz)), has_normal);
    let ambient = globals.ambient.x;
    return ambient + (1.0 - ambient) * diffuse;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.color.rgb * shade(in.normal), in.color.a);
}

// Textured meshes: the base-colour texture (group 1) at the mesh's coordinates (location 9),
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
};

struct TexturedOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) cutoff: f32,
    @location(4) blend: f32,
};

@vertex
fn vs_textured(v: TexturedIn) -> TexturedOut {
    let model = mat4x4<f32>(v.model_0, v.model_1, v.model_2, v.model_3);
    var out: TexturedOut;
    out.clip = globals.view_proj * (model * vec4<f32>(v.position, 1.0));
    out.normal = mat3x3<f32>(v.model_0.xyz, v.model_1.xyz, v.model_2.xyz) * v.normal.xyz;
    out.color = v.color * v.tint;
    out.uv = v.uv;
    out.cutoff = v.params.x;
    out.blend = v.params.y;
    return out;
}

@fragment
fn fs_textured(in: TexturedOut) -> @location(0) vec4<f32> {
    let c = in.color * textureSample(base_color, base_sampler, in.uv);
    if (in.cutoff > 0.0 && c.a < in.cutoff) {
        discard;
    }
    // Alpha counts only for blended materials (glTF: OPAQUE ignores it, MASK is all or nothing).
    let alpha = select(1.0, c.a, in.blend > 0.5);
    return vec4<f32>(c.rgb * shade(in.normal), alpha);
}
