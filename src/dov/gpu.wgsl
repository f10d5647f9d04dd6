// Id cube-map rendering: every fragment writes its object id (with bit 31 set when the triangle
// is seen from behind) into an R32Uint target; reverse-Z depth keeps the nearest surface.

struct Face {
    // Rows: right, up, (0,0,0,near), forward — applied to (position − eye, 1). Clip w is the
    // depth along the face's forward axis, so NDC (x, y) = (u, v) of the cube map and the
    // clip rule 0 ≤ z ≤ w means "depth ≥ near".
    clip_from_rel: mat4x4<f32>,
    // xyz: the sample point, in the same offset frame as the vertex positions.
    eye: vec4<f32>,
};

@group(0) @binding(0) var<uniform> face: Face;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) id: u32,
};

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) id: u32) -> VertexOut {
    var out: VertexOut;
    // Subtract the eye first, in f32, as the CPU ray caster does: keeps precision far from the
    // origin.
    out.clip = face.clip_from_rel * vec4<f32>(position - face.eye.xyz, 1.0);
    out.id = id;
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) u32 {
    if front {
        return in.id;
    }
    return in.id | 0x80000000u;
}
