// Offscreen views: Lambert shading from the face normal (screen-space derivatives of the
// position), a fixed light plus ambient; the colour, the item index and the view depth go to
// three targets.

struct View {
    // Perspective (reverse Z, infinite far) · view, applied to position − eye.
    clip_from_rel: mat4x4<f32>,
    // xyz: unit direction towards the light; w: the ambient share.
    light: vec4<f32>,
    // xyz: unit view direction (depth = rel · forward).
    forward: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    @location(1) @interpolate(flat) id: u32,
    @location(2) @interpolate(flat) color: vec4<f32>,
};

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) id: u32, @location(2) color: u32) -> VertexOut {
    var out: VertexOut;
    out.clip = view.clip_from_rel * vec4<f32>(position, 1.0);
    out.rel = position;
    out.id = id;
    out.color = unpack4x8unorm(color);
    return out;
}

struct FragmentOut {
    @location(0) color: vec4<f32>,
    @location(1) id: u32,
    // The f32 view depth's bits (a u32 target renders on every backend).
    @location(2) depth: u32,
};

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    // Constant over a triangle: its plane's normal, turned towards the eye (two-sided).
    var n = normalize(cross(dpdx(in.rel), dpdy(in.rel)));
    if dot(n, in.rel) > 0.0 {
        n = -n;
    }
    let shade = view.light.w + (1.0 - view.light.w) * max(dot(n, view.light.xyz), 0.0);
    var out: FragmentOut;
    out.color = vec4<f32>(in.color.rgb * shade, 1.0);
    out.id = in.id;
    out.depth = bitcast<u32>(dot(in.rel, view.forward.xyz));
    return out;
}
