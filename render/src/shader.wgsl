// Portico walkthrough shader (client/src/render.rs): per-vertex colour times a per-draw material
// colour, lit by one directional light plus ambient. Lighting is two-sided (|n·l|) because
// building models are drawn without back-face culling.

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

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let len2 = dot(in.normal, in.normal);
    let has_normal = len2 > 1e-12;
    let n = in.normal * inverseSqrt(select(1.0, len2, has_normal));
    let diffuse = select(1.0, abs(dot(n, globals.light_dir.xyz)), has_normal);
    let ambient = globals.ambient.x;
    let shade = ambient + (1.0 - ambient) * diffuse;
    return vec4<f32>(in.color.rgb * shade, in.color.a);
}
