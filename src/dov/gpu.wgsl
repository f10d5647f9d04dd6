// Id cube-map rendering of instanced model-space meshes: every fragment writes its object id
// (with bit 31 set when the triangle is seen from behind) into an R32Uint target; reverse-Z depth
// keeps the nearest surface.

struct Face {
    // Rows: right, up, (0,0,0,near), forward — applied to (position − eye, 1). Clip w is the
    // depth along the face's forward axis, so NDC (x, y) = (u, v) of the cube map and the
    // clip rule 0 ≤ z ≤ w means "depth ≥ near".
    clip_from_rel: mat4x4<f32>,
    // xyz: the sample point, in the same offset frame as the instances' positions.
    eye: vec4<f32>,
};

@group(0) @binding(0) var<uniform> face: Face;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) id_bits: u32,
};

@vertex
fn vs_main(
    @location(0) position: vec3<f32>,
    // The instance: rows of its model → scene-centre affine map, and its id (bit 31: mirrored).
    @location(1) row0: vec4<f32>,
    @location(2) row1: vec4<f32>,
    @location(3) row2: vec4<f32>,
    @location(4) id_bits: u32,
) -> VertexOut {
    let p = vec4<f32>(position, 1.0);
    let rel = vec3<f32>(dot(row0, p), dot(row1, p), dot(row2, p));
    var out: VertexOut;
    // Subtract the eye before projecting, in f32, as the CPU ray caster does: keeps precision far
    // from the origin.
    out.clip = face.clip_from_rel * vec4<f32>(rel - face.eye.xyz, 1.0);
    out.id_bits = id_bits;
    return out;
}

struct FragmentOut {
    @location(0) id_bits: u32,
    @builtin(frag_depth) depth: f32,
};

// How much further a back face is drawn than it lies (1 %, in distance): where the face of a
// solid and the face behind its edge meet in a pixel, the depth test may pick either by the
// rounding of their interpolated depths, worst at grazing angles; the CPU tracer gives such a
// tie to the front face (docs/decisions.md, 136 and 138), and so does this. 0.1 % still let a
// wall seen 0.2° off its plane show the back of the face behind its far edge.
const BACK_FACE_DEPTH_SCALE: f32 = 0.99;

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> FragmentOut {
    var out: FragmentOut;
    // A mirroring instance winds its triangles the other way on screen: its outside shows as
    // "back", so its flag bit flips the test.
    out.id_bits = in.id_bits ^ select(0x80000000u, 0u, front);
    // Reverse Z: depth is near / distance, so a smaller depth lies further away.
    let back = (out.id_bits & 0x80000000u) != 0u;
    out.depth = select(in.clip.z, in.clip.z * BACK_FACE_DEPTH_SCALE, back);
    return out;
}
