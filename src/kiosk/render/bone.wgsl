// Translucent sphere-mesh bones drawn over the statue (an x-ray view of the anatomy).
//
// The default mesh vertex shader places the vertices; here the colour is lit by a key light
// fixed in view space and the opacity rises towards the silhouette (a rim), so overlapping caps
// and cones read as volumes rather than flat blobs.

#import bevy_pbr::forward_io::VertexOutput
#import bevy_pbr::mesh_view_bindings::view

struct BoneParams {
    // Linear RGB and base opacity.
    color: vec4<f32>,
    // View-space direction towards the key light (xyz), ambient (w).
    key_light: vec4<f32>,
    // Hatching (ghost bones): stripe period in world units (x, 0: solid), drawn fraction (y).
    pattern: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> params: BoneParams;

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    if params.pattern.x > 0.0 {
        let along = dot(in.world_position.xyz, vec3<f32>(0.57735, 0.57735, 0.57735));
        if fract(along / params.pattern.x) > params.pattern.y {
            discard;
        }
    }
    let n = normalize(in.world_normal);
    var to_eye = view.world_position - in.world_position.xyz;
    if view.clip_from_view[3][3] == 1.0 {
        to_eye = view.world_from_view[2].xyz;
    }
    let v = normalize(to_eye);
    let ndv = clamp(abs(dot(n, v)), 0.0, 1.0);
    let key = normalize((view.world_from_view * vec4<f32>(params.key_light.xyz, 0.0)).xyz);
    let ambient = params.key_light.w;
    let lambert = ambient + (1.0 - ambient) * max(dot(n, key), 0.0);
    let rim = pow(1.0 - ndv, 2.0);
    let alpha = clamp(params.color.a * (0.45 + 1.8 * rim), 0.0, 0.85);
    let rgb = params.color.rgb * lambert + vec3<f32>(0.25 * rim);
    return vec4<f32>(rgb, alpha);
}
