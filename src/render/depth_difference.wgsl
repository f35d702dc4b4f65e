// Depth-difference outlines (seed 001, Deussen 2003, §4.3): for every pixel, the largest
// positive difference between its neighbours' depth and its own, i.e. how far the pixel lies in
// front of its 8 neighbours. Depth is the camera-frame z (larger = farther); pixels where
// nothing was drawn (depth 0) count as `background` for their neighbours and get 0 themselves.

struct Params {
    background: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
};

@group(0) @binding(0) var depth_in: texture_2d<f32>;
@group(0) @binding(1) var difference_out: texture_storage_2d<r32float, write>;
@group(0) @binding(2) var<uniform> params: Params;

fn depth_or_background(p: vec2<i32>) -> f32 {
    let d = textureLoad(depth_in, p, 0).r;
    if (d <= 0.0) {
        return params.background;
    }
    return d;
}

@compute @workgroup_size(8, 8, 1)
fn depth_difference(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(depth_in));
    let p = vec2<i32>(id.xy);
    if (p.x >= size.x || p.y >= size.y) {
        return;
    }
    let own = textureLoad(depth_in, p, 0).r;
    var largest = 0.0;
    if (own > 0.0) {
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let q = p + vec2<i32>(dx, dy);
                // Outside the image counts as the pixel itself: no outline along the frame.
                if (q.x < 0 || q.y < 0 || q.x >= size.x || q.y >= size.y) {
                    continue;
                }
                largest = max(largest, depth_or_background(q) - own);
            }
        }
    }
    textureStore(difference_out, p, vec4<f32>(largest, 0.0, 0.0, 0.0));
}
