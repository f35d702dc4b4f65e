// Frond render core v1: textured meshes, alpha test (or alpha as coverage), two-sided
// Lambert + ambient light, view-dependent star billboards (quads that give way, atlas rows per
// view elevation), and an id/depth pass writing the object id and the camera-frame depth of
// every pixel.

struct View {
    clip_from_world: mat4x4<f32>,
    // Row 2 of camera_from_world (camera z as a function of the world position) and the
    // light direction toward the light, in world coordinates.
    camera_z_from_world: vec4<f32>,
    light_direction: vec4<f32>,
    // Ambient, key and fill light; w: samples per pixel of the colour pass.
    ambient_diffuse: vec4<f32>,
    // The camera centre in world coordinates.
    eye_world: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;

struct Object {
    id: u32,
    alpha_test: u32,
    // The texture's colour as is (a billboard baked under the scene's light).
    unlit: u32,
    // Added to u on back faces: a two-sided billboard's back tiles.
    back_uv_offset: f32,
    // A billboard baked from several elevations: atlas rows stacked in v (row r at
    // v + r / rows, seen r * elevation_step above the horizon); 1 row for anything else.
    elevation_rows: u32,
    elevation_step: f32,
    // A star billboard's quads (pi / quads apart; 0: draw every quad whole). Quad k is
    // drawn where it is the nearer of the two quads facing the viewer most (angle between its
    // normal and the horizontal view direction), and the two cross-dissolve around halfway:
    // even and odd quads dither with complementary thresholds, so they share the pixels.
    star_quads: u32,
    // The star's vertical axis (x, y in the mesh's frame).
    star_axis_x: f32,
    star_axis_y: f32,
    // A cut-out's alpha is the share of the pixel covered (samples in the colour pass,
    // dithered pixels in the id pass) rather than all or nothing at 0.5.
    alpha_coverage: u32,
    // A billboard's plant height range (mesh frame); its quads reach beyond it by what the
    // highest baked elevation needs. Equal: no trimming.
    plant_z_lo: f32,
    plant_z_hi: f32,
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
    @location(3) world: vec3<f32>,
    // A star billboard's quad index parity (its normal's azimuth in the mesh's frame, so
    // that a rotated instance keeps it).
    @location(4) @interpolate(flat) quad_odd: u32,
    // The same attributes at the centroid of the samples a triangle covers, used with alpha
    // as coverage (level-of-detail foliage and billboards): a pixel that a thin triangle (a
    // leaf seen edge-on) covers in some samples takes them inside the triangle, not
    // extrapolated to the pixel centre, where they read the atlas outside the leaf (a plant
    // seen small lost 11-15 % of its light). Synthetic photos keep the centre's, which
    // their calibrations were measured with.
    @location(5) @interpolate(perspective, centroid) normal_centroid: vec3<f32>,
    @location(6) @interpolate(perspective, centroid) uv_centroid: vec2<f32>,
    @location(7) @interpolate(perspective, centroid) world_centroid: vec3<f32>,
};

// The fragment's attributes: at the centroid of the covered samples for alpha as coverage.
fn attributes(in: VertexOut) -> VertexOut {
    var out = in;
    if (object.alpha_coverage != 0u) {
        out.normal = in.normal_centroid;
        out.uv = in.uv_centroid;
        out.world = in.world_centroid;
    }
    return out;
}

@vertex
fn vs_main(in: VertexIn) -> VertexOut {
    var out: VertexOut;
    let model = mat4x4<f32>(in.model_0, in.model_1, in.model_2, in.model_3);
    var position = in.position;
    var uv = in.uv;
    // A billboard's quad reaches `overhang` above and below the plant for the highest baked
    // elevation; a lower view needs less of it (with two row steps to spare for the row
    // blend and the view's spread over the plant), so the corner moves in and v with it
    // (v grows downwards by 1 / rows over the quad's height).
    let rows = object.elevation_rows;
    let lo = object.plant_z_lo;
    let hi = object.plant_z_hi;
    if (rows > 1u && hi > lo) {
        let top = position.z > hi;
        let overhang = select(lo - position.z, position.z - hi, top);
        let highest = object.elevation_step * f32(rows - 1u);
        if (overhang > 0.0 && highest > 0.0) {
            let centre = model * vec4<f32>(object.star_axis_x, object.star_axis_y,
                                           0.5 * (lo + hi), 1.0);
            let to_eye = normalize(view.eye_world.xyz - centre.xyz);
            let elevation = asin(clamp(abs(to_eye.z), 0.0, 1.0));
            let needed_elevation = min(elevation + 2.0 * object.elevation_step, highest);
            let needed = overhang * tan(needed_elevation) / tan(highest);
            let z = select(lo - needed, hi + needed, top);
            let quad_height = (hi - lo) + 2.0 * overhang;
            uv.y = uv.y + (position.z - z) / (f32(rows) * quad_height);
            position.z = z;
        }
    }
    let world = model * vec4<f32>(position, 1.0);
    out.clip = view.clip_from_world * world;
    out.normal = (model * vec4<f32>(in.normal, 0.0)).xyz;
    out.uv = uv;
    out.depth = dot(view.camera_z_from_world, world);
    out.world = world.xyz;
    out.quad_odd = 0u;
    // A star billboard's quad more than the quads' spacing from facing a viewer on its axis
    // gives way in every fragment (the fragment stage drops it from 0.65 spacing on): its
    // corners collapse outside the view, so it is not rasterized.
    if (object.star_quads > 0u && dot(in.normal.xy, in.normal.xy) > 1e-12) {
        // Quad k's normal is (-sin a, cos a), a = k pi / quads.
        let spacing = 3.14159265 / f32(object.star_quads);
        let k = i32(round(atan2(-in.normal.x, in.normal.y) / spacing));
        let q = i32(object.star_quads);
        out.quad_odd = u32((((k % q) + q) % q) % 2);
        let axis = model * vec4<f32>(object.star_axis_x, object.star_axis_y, in.position.z, 1.0);
        let horizontal = view.eye_world.xy - axis.xy;
        let normal = out.normal.xy;
        if (dot(horizontal, horizontal) > 1e-12 && dot(normal, normal) > 1e-12) {
            let facing = abs(dot(normalize(horizontal), normalize(normal)));
            if (acos(min(facing, 1.0)) > spacing) {
                out.clip = vec4<f32>(2.0, 2.0, 2.0, 1.0);
            }
        }
    }
    out.normal_centroid = out.normal;
    out.uv_centroid = out.uv;
    out.world_centroid = out.world;
    return out;
}

fn face_uv(uv: vec2<f32>, front: bool) -> vec2<f32> {
    if (front) {
        return uv;
    }
    return vec2<f32>(uv.x + object.back_uv_offset, uv.y);
}

// A 4x4 Bayer threshold in (0, 1) for the pixel at `pixel`.
fn dither_threshold(pixel: vec2<f32>) -> f32 {
    let x = u32(pixel.x) % 4u;
    let y = u32(pixel.y) % 4u;
    let bayer = array<f32, 16>(0.0, 8.0, 2.0, 10.0, 12.0, 4.0, 14.0, 6.0,
                               3.0, 11.0, 1.0, 9.0, 15.0, 7.0, 13.0, 5.0);
    return (bayer[y * 4u + x] + 0.5) / 16.0;
}

// The surface's texel: for a billboard, the two atlas rows baked nearest the view's
// elevation blended, and alpha 0 where the quad gives way to one facing the viewer more.
fn surface_texel(in: VertexOut, front: bool) -> vec4<f32> {
    let uv = face_uv(in.uv, front);
    if (object.elevation_rows <= 1u && object.star_quads == 0u) {
        if (object.alpha_coverage != 0u) {
            // The mip level of the footprint's shorter side: a leaf seen nearly edge-on keeps
            // the alpha of its own texels instead of one averaged over its long side with
            // the transparent texels around it (which thinned distant foliage).
            let size = vec2<f32>(textureDimensions(base_color));
            let shorter = min(length(dpdx(uv) * size), length(dpdy(uv) * size));
            return textureSampleLevel(base_color, base_sampler, uv, log2(max(shorter, 1e-6)));
        }
        return textureSample(base_color, base_sampler, uv);
    }
    // Gradients taken before any branch that depends on the fragment, so that a quad that
    // gives way skips its texture lookups (textureSampleGrad needs no uniform control flow).
    var uv_dx = dpdx(uv);
    var uv_dy = dpdy(uv);
    {
        let size = vec2<f32>(textureDimensions(base_color));
        let lx = length(uv_dx * size);
        let ly = length(uv_dy * size);
        let shorter = max(min(lx, ly), 1e-6);
        uv_dx = uv_dx * min(1.0, shorter / max(lx, 1e-6));
        uv_dy = uv_dy * min(1.0, shorter / max(ly, 1e-6));
    }
    let to_eye = normalize(view.eye_world.xyz - in.world);
    let horizontal = to_eye.xy;
    let normal = in.normal.xy;
    if (object.star_quads > 0u && dot(horizontal, horizontal) > 1e-12
        && dot(normal, normal) > 1e-12) {
        let spacing = 3.14159265 / f32(object.star_quads);
        let n = normalize(normal);
        let facing = abs(dot(normalize(horizontal), n));
        // Each pixel shows the nearer quad, except around halfway between two quads (the
        // middle 30 % of their spacing), where they cross-dissolve by dithering.
        let weight = smoothstep(0.35, 0.65, 1.0 - acos(min(facing, 1.0)) / spacing);
        var threshold = dither_threshold(in.clip.xy);
        if (in.quad_odd == 1u) {
            threshold = 1.0 - threshold;
        }
        if (weight <= threshold) {
            return vec4<f32>(0.0);
        }
    }
    let rows = f32(max(object.elevation_rows, 1u));
    let elevation = asin(clamp(to_eye.z, 0.0, 1.0));
    let row = clamp(elevation / max(object.elevation_step, 1e-6), 0.0, rows - 1.0);
    let low = floor(row);
    let high = min(low + 1.0, rows - 1.0);
    let a = textureSampleGrad(base_color, base_sampler, vec2<f32>(uv.x, uv.y + low / rows),
                              uv_dx, uv_dy);
    let b = textureSampleGrad(base_color, base_sampler, vec2<f32>(uv.x, uv.y + high / rows),
                              uv_dx, uv_dy);
    return mix(a, b, row - low);
}

// Alpha is the share of a pixel the surface covers there, drawn as that share of the
// pixel's samples (a billboard's mips; leaves thinner than a pixel).
fn uses_alpha_coverage() -> bool {
    return object.alpha_coverage != 0u;
}

// A dither threshold that does not repeat the quads' (a shifted Bayer pattern).
fn coverage_threshold(pixel: vec2<f32>) -> f32 {
    return dither_threshold(pixel + vec2<f32>(2.0, 1.0));
}

// round(alpha x samples) samples (stochastically rounded by the pixel's dither) of the
// colour pass, starting at a sample that changes from pixel to pixel.
fn coverage_mask(alpha: f32, pixel: vec2<f32>) -> u32 {
    let samples = clamp(u32(view.ambient_diffuse.w), 1u, 8u);
    let n = min(u32(floor(clamp(alpha, 0.0, 1.0) * f32(samples) + coverage_threshold(pixel))),
                samples);
    let covered = (1u << n) - 1u;
    let r = (u32(pixel.x) + 2u * u32(pixel.y)) % samples;
    let all = (1u << samples) - 1u;
    return ((covered << r) | (covered >> (samples - r))) & all;
}

struct ColorOut {
    @location(0) color: vec4<f32>,
    @builtin(sample_mask) mask: u32,
};

@fragment
fn fs_color(raw: VertexOut, @builtin(front_facing) front: bool) -> ColorOut {
    let in = attributes(raw);
    let texel = surface_texel(in, front);
    var out: ColorOut;
    out.mask = 0xffffffffu;
    if (object.alpha_test != 0u) {
        if (uses_alpha_coverage()) {
            out.mask = coverage_mask(texel.a, in.clip.xy);
            if (out.mask == 0u) {
                discard;
            }
        } else if (texel.a < 0.5) {
            discard;
        }
    }
    out.color = shaded(in, front, texel);
    return out;
}

fn shaded(in: VertexOut, front: bool, texel: vec4<f32>) -> vec4<f32> {
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
fn fs_id(raw: VertexOut, @builtin(front_facing) front: bool) -> IdOut {
    let in = attributes(raw);
    let texel = surface_texel(in, front);
    // One sample per pixel: a partial alpha drawn as coverage covers that share of the
    // pixels, as it covers that share of the colour pass's samples.
    var cutoff = 0.5;
    if (uses_alpha_coverage()) {
        cutoff = max(coverage_threshold(in.clip.xy), 1e-3);
    }
    if (object.alpha_test != 0u && texel.a < cutoff) {
        discard;
    }
    var out: IdOut;
    out.id = object.id;
    out.depth = in.depth;
    return out;
}
