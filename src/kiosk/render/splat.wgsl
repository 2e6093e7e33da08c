// Oriented point splats (Pygmalion kiosk).
//
// Every point of the statue is four vertices; their `index` attribute is 4 · point + corner.
// The point's centre and normal are read from the storage buffer `points` (6 floats per
// point, rewritten when the statue is re-posed; the mesh itself never changes), the corner
// (±1, ±1) from `CORNERS`. The vertex shader spreads the corners over a
// square of half-side `r` in the plane orthogonal to the point's normal (turned towards the
// camera when the normal is seen nearly edge-on), and the fragment shader keeps the inscribed
// disc and shades it: two-sided soft Lambert with a key light fixed in view space (the statue
// is lit the same way whichever way a visitor turns it), plus ambient, plus an optional
// darkening of surfaces seen at grazing angles (a cheap stand-in for eye-dome edges).

#import bevy_pbr::mesh_functions
#import bevy_pbr::mesh_view_bindings::view

struct SplatParams {
    // sRGB albedo multiplied with the point's colour (white when the scan has none).
    base_color: vec4<f32>,
    // View-space direction towards the key light (xyz) and the ambient term (w).
    key_light: vec4<f32>,
    // World radius of a splat (from the point density).
    radius: f32,
    // Smallest on-screen radius in pixels (far away statues keep a closed surface).
    min_pixels: f32,
    // |n·v| below which a splat turns to face the camera.
    edge_on: f32,
    // Strength of the grazing-angle darkening (0 = off).
    edges: f32,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> params: SplatParams;
// Per point: x y z nx ny nz.
@group(#{MATERIAL_BIND_GROUP}) @binding(1) var<storage, read> points: array<f32>;

struct SplatVertex {
    @builtin(instance_index) instance_index: u32,
    @location(0) index: u32,
    @location(1) color: vec4<f32>,
}

struct SplatVarying {
    @builtin(position) clip_position: vec4<f32>,
    @location(0) corner: vec2<f32>,
    @location(1) albedo: vec3<f32>,
    // World normal turned towards the camera (two-sided shading).
    @location(2) normal: vec3<f32>,
    // |n·v| of the original normal.
    @location(3) facing: f32,
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    return pow(c, vec3<f32>(2.2));
}

@vertex
fn vertex(v: SplatVertex) -> SplatVarying {
    let i = 6u * (v.index >> 2u);
    let c = v.index & 3u;
    // CORNERS: (-1, -1), (1, -1), (1, 1), (-1, 1).
    let corner = vec2<f32>(select(-1.0, 1.0, c == 1u || c == 2u), select(-1.0, 1.0, c >= 2u));
    let local_center = vec3<f32>(points[i], points[i + 1u], points[i + 2u]);
    let local_normal = vec3<f32>(points[i + 3u], points[i + 4u], points[i + 5u]);
    let world_from_local = mesh_functions::get_world_from_local(v.instance_index);
    let center = (world_from_local * vec4<f32>(local_center, 1.0)).xyz;

    // Direction to the eye (orthographic views look along the view's -Z).
    var to_eye = view.world_position - center;
    if view.clip_from_view[3][3] == 1.0 {
        to_eye = view.world_from_view[2].xyz;
    }
    to_eye = normalize(to_eye);

    var n = mesh_functions::mesh_normal_local_to_world(local_normal, v.instance_index);
    let n_len = length(n);
    if n_len < 1e-6 || n_len != n_len {
        n = to_eye;
    } else {
        n = n / n_len;
    }
    let facing = dot(n, to_eye);
    let front = select(-n, n, facing >= 0.0);
    let a = abs(facing);
    // 0 for splats seen face-on enough, 1 for splats seen edge-on: those face the camera.
    let turn = 1.0 - smoothstep(0.25 * params.edge_on, params.edge_on, a);
    let disc_n = normalize(mix(front, to_eye, turn));

    let helper = select(vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), abs(disc_n.y) > 0.9);
    let t1 = normalize(cross(disc_n, helper));
    let t2 = cross(disc_n, t1);

    // Keep at least `min_pixels` of radius on screen.
    let clip_center = view.clip_from_world * vec4<f32>(center, 1.0);
    let px_per_unit = view.clip_from_view[1][1] * 0.5 * view.viewport.w / max(abs(clip_center.w), 1e-6);
    let r = max(params.radius, params.min_pixels / max(px_per_unit, 1e-6));

    let p = center + (t1 * corner.x + t2 * corner.y) * r;

    var out: SplatVarying;
    out.clip_position = view.clip_from_world * vec4<f32>(p, 1.0);
    out.corner = corner;
    out.albedo = params.base_color.rgb * v.color.rgb;
    out.normal = front;
    out.facing = a;
    return out;
}

@fragment
fn fragment(in: SplatVarying) -> @location(0) vec4<f32> {
    let d2 = dot(in.corner, in.corner);
    if d2 > 1.0 {
        discard;
    }
    let n = normalize(in.normal);
    let key = normalize((view.world_from_view * vec4<f32>(params.key_light.xyz, 0.0)).xyz);
    // Two-sided Lambert (scan normals are not always consistently oriented), softened a little.
    let lambert = pow(abs(dot(n, key)), 0.8);
    let ambient = params.key_light.w;
    var shade = ambient + (1.0 - ambient) * lambert;
    // Grazing surfaces darken: outlines the silhouette and the folds.
    shade = shade * mix(1.0, 0.5 + 0.5 * smoothstep(0.0, 0.5, in.facing), params.edges);
    // A slight falloff towards the rim of each disc hides the seams between splats.
    shade = shade * (1.0 - 0.08 * d2);
    // Shading is applied to sRGB values (as the CPU renderer does), then made linear for the
    // sRGB target: this keeps the contrast of a drawing rather than a washed-out photograph.
    return vec4<f32>(srgb_to_linear(clamp(in.albedo * shade, vec3<f32>(0.0), vec3<f32>(1.0))), 1.0);
}
