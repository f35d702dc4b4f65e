// Frond render core v1: textured meshes, alpha test, two-sided Lambert + ambient light,
// and an id/depth pass writing the object id and the camera-frame depth of every pixel.

struct View {
    clip_from_world: mat4x4<f32>,
    // Row 2 of camera_from_world (camera z as a function of the world position) and the
    // light direction toward the light, in world coordinates.
    camera_z_from_world: vec4<f32>,
    light_direction: vec4<f32>,
    ambient_diffuse: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;

struct Object {
    id: u32,
    alpha_test: u32,
    // The texture's colour as is (a billboard baked under the scene's light).
    unlit: u32,
    // Added to u on back faces: a two-sided billboard's back tiles.
    back_uv_offset: f32,
};

@group(1) @binding(0) var<uniform> object: Object;
@group(1) @binding(1) var base_color: texture_2d<f32>;
@group(1) @binding(2) var base_sampler: sampler;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    // Model-to-world transform of the instance (identity for static meshes), by columns.
    @location(3) model_0: vec4<f32>,
    @location(4) model_1: vec4<f32>,
    @location(5) model_2: vec4<f32>,
    @location(6) model_3: vec4<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) depth: f32,
};

@vertex
fn vs_main(in: VertexIn) -> VertexOut {
    var out: VertexOut;
    let model = mat4x4<f32>(in.model_0, in.model_1, in.model_2, in.model_3);
    let world = model * vec4<f32>(in.position, 1.0);
    out.clip = view.clip_from_world * world;
    out.normal = (model * vec4<f32>(in.normal, 0.0)).xyz;
    out.uv = in.uv;
    out.depth = dot(view.camera_z_from_world, world);
    return out;
}

fn face_uv(uv: vec2<f32>, front: bool) -> vec2<f32> {
    if (front) {
        return uv;
    }
    return vec2<f32>(uv.x + object.back_uv_offset, uv.y);
}

@fragment
fn fs_color(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let texel = textureSample(base_color, base_sampler, face_uv(in.uv, front));
    if (object.alpha_test != 0u && texel.a < 0.5) {
        discard;
    }
    if (object.unlit != 0u) {
        return vec4<f32>(texel.rgb, 1.0);
    }
    var n = normalize(in.normal);
    if (!front) {
        n = -n;
    }
    let l = normalize(view.light_direction.xyz);
    let key = max(dot(n, l), 0.0);
    let fill = max(dot(n, normalize(vec3<f32>(-l.x, -l.y, 0.6))), 0.0);
    let shade = view.ambient_diffuse.x + view.ambient_diffuse.y * key + view.ambient_diffuse.z * fill;
    return vec4<f32>(texel.rgb * shade, 1.0);
}

struct IdOut {
    @location(0) id: u32,
    @location(1) depth: f32,
};

@fragment
fn fs_id(in: VertexOut, @builtin(front_facing) front: bool) -> IdOut {
    let texel = textureSample(base_color, base_sampler, face_uv(in.uv, front));
    if (object.alpha_test != 0u && texel.a < 0.5) {
        discard;
    }
    var out: IdOut;
    out.id = object.id;
    out.depth = in.depth;
    return out;
}
