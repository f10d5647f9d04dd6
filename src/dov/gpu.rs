//! The GPU backend: wgpu rasterisation of the id cube map.
//!
//! **Instanced drawing.** Each base mesh is uploaded once, in model space (positions + a u32
//! index buffer), followed by its coarser leaf LODs when [`GpuOptions::lods`] is given; an
//! instance buffer holds per object its transform (rows of `T(−origin)·M`, so positions come out
//! relative to the scene's centre and f32 precision stays near the geometry) and its id, with
//! [`super::BACK_FACE_BIT`] set for a mirroring transform (negative determinant: its triangles
//! wind the other way on screen, so the fragment shader flips the front-facing test). GPU memory
//! is thus the base meshes once plus 52 bytes per object, instead of every instance's
//! triangles in world space (docs/dov.md, "GPU memory").
//!
//! **Draw order is descending id**, as the CPU backend's tie rule needs among faces seen from one
//! side: with a `GreaterEqual` reverse-Z depth test the later-drawn lower id wins an exact depth
//! tie. **Back faces are drawn 1 % further than they lie** (the fragment shader writes their
//! depth scaled by `BACK_FACE_DEPTH_SCALE`), so that where the face of a solid and the face
//! behind its edge meet in a pixel at depths that rounding or a grazing angle blurs (a slab's far
//! edge, a wall seen along its length), the front wins, as the CPU's tie rule has it within its
//! far narrower window (decision 138). Instances lie in the
//! instance buffer in descending id order; per face, the objects that survive the frustum test
//! become draw commands in that order, consecutive objects with the same base mesh and level
//! merged into one instanced draw. Where the device has indirect draws with a first instance
//! ([`crate::gfx::Gpu::indirect_draws`]) the commands go out as one `multi_draw_indexed_indirect`
//! per face, otherwise as direct `draw_indexed` calls (same commands, same pixels).
//!
//! Each face is rendered into its own R32Uint 2D texture (copying 2D-array layers to a buffer
//! reads back zeros on the GL backend), then all six are copied into one mapped buffer and
//! weighed on the CPU with [`super::IdCube::dov`], exactly as the CPU backend's ids are.
//!
//! **LOD-aware drawing** ([`GpuBackend::with_options`] with [`GpuOptions::lods`]): per sample
//! point each object is drawn at the coarsest level whose world-space error (the level's error
//! times the transform's largest axis scale), seen from the point at the distance of the
//! object's box, subtends less than [`GpuOptions::lod_tolerance_texels`] texels at the face
//! centre (a texel there spans 2/R radians): [`crate::lod::coarsest_below`]. An object whose box
//! contains the point is drawn at full detail. docs/dov.md ("LOD-aware drawing") has the
//! measured DoV change and speed-up.

use glam::{Mat4, Vec3, Vec4};
use wgpu::util::DrawIndexedIndirectArgs;

use super::cpu::{check_cube, check_point, check_resolution_and_near};
use super::cubemap::{FACE_COUNT, FaceBasis, face_basis};
use super::sampling::RegionViews;
use super::{BACK_FACE_BIT, CubeMap, DovBackend, IdCube, NO_OBJECT};
use crate::error::{Error, Param, Result};
use crate::geom::{Aabb, max_scale};
use crate::gfx::Gpu;
use crate::lod::{LodLevel, coarsest_below};
use crate::scene::{Mesh, Scene};

/// Bytes between the six per-face uniform blocks (the largest `min_uniform_buffer_offset_alignment`
/// wgpu allows).
const UNIFORM_STRIDE: u64 = 256;

/// Default of [`GpuOptions::lod_tolerance_texels`] (the build parameter's default).
pub use crate::format::params::DEFAULT_LOD_TOLERANCE_TEXELS;

/// Construction options of [`GpuBackend::with_options`].
#[derive(Clone, Copy, Debug)]
pub struct GpuOptions<'a> {
    /// Near distance along each face's forward axis; `None`: [`super::default_near`] of the scene.
    pub near: Option<f32>,
    /// Leaf LOD chains per base mesh (finest first, as [`crate::lod::SceneLods::leaf`]), to draw
    /// each object at the coarsest level the measurement cannot tell apart; `None`: always full
    /// detail. Level 0 is not used: full detail is always the scene's own triangles.
    pub lods: Option<&'a [Vec<LodLevel>]>,
    /// An object is drawn at a level whose world error / distance to the object's box is below
    /// this many texels at the face centre (each 2/R radians). 0 draws full detail throughout.
    pub lod_tolerance_texels: f32,
    /// Issue direct `draw_indexed` calls even where the device could take one indirect
    /// multi-draw per face: the same commands and pixels, for testing and timing the fallback.
    pub direct_draws: bool,
    /// Draw region sampling as region views of this many texels a face edge
    /// ([`DovBackend::region_views`]); 0: leave region rays to the CPU caster.
    pub region_views: u32,
}

impl Default for GpuOptions<'_> {
    fn default() -> Self {
        Self {
            near: None,
            lods: None,
            lod_tolerance_texels: DEFAULT_LOD_TOLERANCE_TEXELS,
            direct_draws: false,
            region_views: 0,
        }
    }
}

pub use crate::gfx::{adapter_available, hardware_adapter_available};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FaceUniform {
    clip_from_rel: [[f32; 4]; 4],
    eye: [f32; 4],
}

/// One instance: rows 0–2 of the affine map from model space to positions relative to the
/// scene's centre, and the object id with [`BACK_FACE_BIT`] set when the transform mirrors.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Instance {
    rows: [[f32; 4]; 3],
    id_bits: u32,
}

impl Instance {
    /// Shader locations 1–3 (`vec4<f32>` rows) and 4 (`u32` id bits), one step per instance.
    const ATTRIBUTES: [wgpu::VertexAttribute; 4] =
        wgpu::vertex_attr_array![1 => Float32x4, 2 => Float32x4, 3 => Float32x4, 4 => Uint32];

    /// `T(−origin)·m`, composed in f64 and rounded once to f32 (the transform's last row is
    /// taken as (0, 0, 0, 1), as `Mat4::transform_point3` takes it).
    fn new(m: &Mat4, origin: Vec3, id: u32) -> Self {
        let row = |i: usize| {
            let t = f64::from(m.w_axis[i]) - f64::from(origin[i]);
            [m.x_axis[i], m.y_axis[i], m.z_axis[i], t as f32]
        };
        let mirrored = if m.determinant() < 0.0 { BACK_FACE_BIT } else { 0 };
        Self { rows: [row(0), row(1), row(2)], id_bits: id | mirrored }
    }
}

/// Model-space position layout (shader location 0), one step per vertex.
const POSITION_ATTRIBUTES: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];

/// One level of one base mesh in the shared position and index buffers.
#[derive(Clone, Copy, Debug)]
struct MeshLevel {
    first_index: u32,
    index_count: u32,
    base_vertex: i32,
    /// The simplifier's error in model units (0 for full detail).
    error: f32,
}

/// One object, in draw (descending id) order; its instance index is its position in that order.
#[derive(Clone, Debug)]
struct DrawObject {
    mesh: u32,
    /// The transform's largest axis scale: model errors times it are world errors.
    scale: f32,
    /// World bounds relative to `origin` of every level's vertices (culling must keep a coarse
    /// level that bulges out of the full-detail box).
    bounds: Aabb,
}

/// Rasterises the id cube around a point with wgpu. Construction uploads the base meshes (and
/// their LODs) once in model space plus one instance per object, and allocates the render
/// targets; each [`DovBackend::render_ids`] does 6 render passes (objects culled per face by
/// their boxes), one copy and one blocking read-back of 6·R²·4 bytes.
pub struct GpuBackend {
    cube: CubeMap,
    near: f32,
    gpu: Gpu,
    pipeline: wgpu::RenderPipeline,
    uniforms: wgpu::Buffer,
    bind_layout: wgpu::BindGroupLayout,
    face_bind_groups: Vec<wgpu::BindGroup>,
    /// Texels per face edge of region views; 0: none drawn.
    region_resolution: u32,
    /// Region views' targets, made at the first [`DovBackend::region_views`].
    region: Option<RegionTargets>,
    /// Model-space positions, indices and instances; `None` for an empty scene.
    geometry: Option<GeometryBuffers>,
    /// Per base mesh, its levels finest first (only level 0 without LODs).
    mesh_levels: Vec<Vec<MeshLevel>>,
    objects: Vec<DrawObject>,
    /// One face's draw commands at most per object, six faces: `None` with direct draws.
    indirect: Option<wgpu::Buffer>,
    /// Largest world error / distance drawn at a coarser level (radians); 0 without LODs.
    lod_max_angle: f32,
    /// Triangles drawn since construction, over all faces and points.
    triangles_drawn: u64,
    /// Draw commands (instanced draws) issued since construction.
    draw_commands: u64,
    bytes_uploaded: u64,
    origin: Vec3,
    face_targets: Vec<(wgpu::Texture, wgpu::TextureView)>,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row_bytes: u32,
}

/// Texel rows of the atlas that region views are drawn into ([`DovBackend::region_views`]): one
/// view a row of views, its six faces side by side; as many views a render pass as fill it.
const REGION_ATLAS_ROWS: u32 = 512;

/// The atlas that region views are drawn into (row `v` of views: view `v` of a batch, column
/// `f` of faces: its face `f`), its depth buffer and read-back, and one uniform block and bind
/// group per face of every view of a batch.
struct RegionTargets {
    atlas: wgpu::Texture,
    atlas_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row_bytes: u32,
    uniforms: wgpu::Buffer,
    bind_groups: Vec<wgpu::BindGroup>,
    /// A batch's draw commands, grown as needed; `None` with direct draws.
    indirect: Option<wgpu::Buffer>,
}

struct GeometryBuffers {
    positions: wgpu::Buffer,
    indices: wgpu::Buffer,
    instances: wgpu::Buffer,
}

impl GpuBackend {
    /// Opens an adapter and uploads `scene` for measurements at `resolution`, with the near
    /// plane of [`super::default_near`]. Fails with [`Error::Gpu`] when no adapter or device can
    /// be had, or the scene or resolution exceed the device's limits.
    pub fn new(scene: &Scene, resolution: u32) -> Result<Self> {
        Self::with_near(scene, resolution, super::default_near(&scene.bounds()))
    }

    /// As [`GpuBackend::new`] with an explicit near distance along each face's forward axis.
    pub fn with_near(scene: &Scene, resolution: u32, near: f32) -> Result<Self> {
        Self::with_options(scene, resolution, &GpuOptions { near: Some(near), ..Default::default() })
    }

    /// As [`GpuBackend::new`] with [`GpuOptions`]: near plane, LOD-aware drawing and the draw
    /// calls. With `options.lods`, every coarser level of every base mesh is uploaded as well
    /// (model space, once per base mesh).
    /// Fails with [`Error::BadParam`] when `lods` has not one chain per base mesh, the tolerance
    /// is negative or not finite, or the scene has more objects than ids can carry.
    pub fn with_options(scene: &Scene, resolution: u32, options: &GpuOptions) -> Result<Self> {
        let near = options.near.unwrap_or_else(|| super::default_near(&scene.bounds()));
        check_resolution_and_near(resolution, near)?;
        let tolerance = options.lod_tolerance_texels;
        if !(tolerance.is_finite() && tolerance >= 0.0) {
            return Err(Error::bad_param(Param::LodDrawTolerance, format!("{tolerance} must be finite and >= 0")));
        }
        let max = crate::format::params::MAX_REGION_VIEW_RESOLUTION;
        if options.region_views > max {
            return Err(Error::bad_param(Param::RegionViews, format!("{} texels is outside 0..={max}", options.region_views)));
        }
        if let Some(lods) = options.lods
            && lods.len() != scene.meshes.len()
        {
            return Err(Error::bad_param(
                Param::Lods,
                format!("{} chains for {} base meshes", lods.len(), scene.meshes.len()),
            ));
        }
        super::check_object_count(scene)?;
        let gpu = Gpu::open("hdov dov")?;
        let limit = gpu.limits.max_texture_dimension_2d;
        if resolution > limit {
            return Err(Error::Gpu(format!("resolution {resolution} exceeds the adapter's texture limit {limit}")));
        }
        let device = &gpu.device;

        // Validation and out-of-memory errors become `Error::Gpu` instead of wgpu's default panic.
        // (Scopes pop in reverse order; an early return drops them in reverse order too.)
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out_of_memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let origin = scene.bounds().center();
        let origin = if origin.is_finite() { origin } else { Vec3::ZERO };
        let model = ModelGeometry::build(scene, options.lods)?;
        let objects = draw_objects(scene, options.lods, origin);
        let instances: Vec<Instance> = (0..scene.objects.len())
            .rev()
            .map(|o| Instance::new(&scene.objects[o].transform, origin, o as u32))
            .collect();
        let bytes_uploaded = std::mem::size_of_val(&model.positions[..])
            + std::mem::size_of_val(&model.indices[..])
            + std::mem::size_of_val(&instances[..]);
        let geometry = match (
            gpu.upload("dov model positions", bytemuck::cast_slice(&model.positions), wgpu::BufferUsages::VERTEX)?,
            gpu.upload("dov model indices", bytemuck::cast_slice(&model.indices), wgpu::BufferUsages::INDEX)?,
            gpu.upload("dov instances", bytemuck::cast_slice(&instances), wgpu::BufferUsages::VERTEX)?,
        ) {
            (Some(positions), Some(indices), Some(instances)) => {
                Some(GeometryBuffers { positions, indices, instances })
            }
            _ => None,
        };
        drop(instances);
        let indirect = (gpu.indirect_draws && !options.direct_draws && geometry.is_some()).then(|| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("dov draw commands"),
                size: (FACE_COUNT * objects.len() * std::mem::size_of::<DrawIndexedIndirectArgs>()) as u64,
                usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });

        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("dov face uniforms"),
            size: UNIFORM_STRIDE * FACE_COUNT as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_layout = crate::gfx::uniform_layout::<FaceUniform>(device, "dov face", wgpu::ShaderStages::VERTEX);
        let face_bind_groups = face_bind_groups(device, &bind_layout, &uniforms, FACE_COUNT);
        let pipeline = create_pipeline(device, &bind_layout);

        let face_targets = (0..FACE_COUNT)
            .map(|_| {
                let texture = gpu.target("dov id face", resolution, resolution, wgpu::TextureFormat::R32Uint);
                let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
                (texture, view)
            })
            .collect();
        let depth = gpu.depth_buffer("dov depth", resolution, resolution);
        let depth_view = depth.create_view(&wgpu::TextureViewDescriptor::default());
        let padded_row_bytes = crate::gfx::padded_row_bytes(resolution, 4);
        let readback =
            gpu.readback_buffer("dov readback", padded_row_bytes as u64 * resolution as u64 * FACE_COUNT as u64);
        for scope in [out_of_memory, validation] {
            if let Some(e) = pollster::block_on(scope.pop()) {
                return Err(Error::Gpu(format!("{}: setting up: {e}", gpu.adapter_name)));
            }
        }
        Ok(Self {
            cube: CubeMap::new(resolution),
            near,
            gpu,
            pipeline,
            uniforms,
            bind_layout,
            face_bind_groups,
            region_resolution: options.region_views,
            region: None,
            geometry,
            mesh_levels: model.levels,
            objects,
            indirect,
            lod_max_angle: if options.lods.is_some() { tolerance * 2.0 / resolution as f32 } else { 0.0 },
            triangles_drawn: 0,
            draw_commands: 0,
            bytes_uploaded: bytes_uploaded as u64,
            origin,
            face_targets,
            depth_view,
            readback,
            padded_row_bytes,
        })
    }

    /// The adapter's name, driver and backend, e.g. "llvmpipe (...) on Vulkan".
    pub fn adapter_name(&self) -> &str {
        &self.gpu.adapter_name
    }

    pub fn near(&self) -> f32 {
        self.near
    }

    /// Triangles drawn since construction, summed over every face of every rendering.
    pub fn triangles_drawn(&self) -> u64 {
        self.triangles_drawn
    }

    /// Draw commands (one instanced draw of one mesh level each) issued since construction.
    pub fn draw_commands(&self) -> u64 {
        self.draw_commands
    }

    /// Bytes of geometry uploaded at construction: model-space positions (12 per vertex) and
    /// indices (4 per corner) of every base mesh level, and 52 per instance. Per rendering only
    /// the face uniforms and draw commands are written (not counted here).
    pub fn bytes_uploaded(&self) -> u64 {
        self.bytes_uploaded
    }

    /// Whether the draw commands go out as one indirect multi-draw per face (else direct draws).
    pub fn indirect_draws(&self) -> bool {
        self.indirect.is_some()
    }

    /// Whether LOD-aware drawing is on (LODs given and a tolerance above 0).
    pub fn lod_drawing(&self) -> bool {
        self.lod_max_angle > 0.0
    }

    /// Per object in draw order, the level to draw from `eye` ([`coarsest_below`] of its world
    /// errors against the tolerance angle times the distance to its box); full detail when the
    /// box contains the eye.
    fn chosen_levels(&self, eye: Vec3) -> Vec<u32> {
        self.objects
            .iter()
            .map(|o| {
                let levels = &self.mesh_levels[o.mesh as usize];
                if levels.len() == 1 || self.lod_max_angle <= 0.0 {
                    return 0;
                }
                // Distance from the eye to the box (0 inside it, so full detail there).
                let distance = (o.bounds.min - eye).max(eye - o.bounds.max).max(Vec3::ZERO).length();
                coarsest_below(levels.iter().map(|l| l.error * o.scale), self.lod_max_angle * distance) as u32
            })
            .collect()
    }

    /// Draw commands for one face: objects whose box may reach into the face's frustum, at the
    /// levels in `chosen` (one per object in draw order), in draw order, consecutive instances of
    /// the same mesh level merged into one command. Conservative: a box is dropped only when it
    /// lies wholly outside one of the frustum's planes (or wholly nearer than the near plane).
    fn face_commands(&self, b: FaceBasis, eye: Vec3, chosen: &[u32], out: &mut Vec<DrawIndexedIndirectArgs>) {
        // Inside the frustum: n·d ≥ 0 for each side normal, forward·d ≥ near.
        let sides = [b.forward - b.right, b.forward + b.right, b.forward - b.up, b.forward + b.up];
        let first = out.len();
        for (instance, (object, &level)) in self.objects.iter().zip(chosen).enumerate() {
            let level = self.mesh_levels[object.mesh as usize][level as usize];
            if level.index_count == 0 {
                continue;
            }
            let bounds = &object.bounds;
            let centre = bounds.center() - eye;
            let half = bounds.extent() * 0.5;
            // The box's largest value of n·d; slack covers rounding at the planes.
            let reach = |n: Vec3| n.dot(centre) + n.abs().dot(half);
            let slack = 1e-5 * (centre.length() + half.length());
            let outside = sides.iter().any(|&n| reach(n) < -slack) || reach(b.forward) < self.near - slack;
            if outside {
                continue;
            }
            let instance = instance as u32;
            // Only this face's commands may be extended.
            let face_has_commands = out.len() > first;
            match out.last_mut() {
                Some(last)
                    if face_has_commands
                        && last.first_index == level.first_index
                        && last.base_vertex == level.base_vertex
                        && last.first_instance + last.instance_count == instance =>
                {
                    last.instance_count += 1
                }
                _ => out.push(DrawIndexedIndirectArgs {
                    index_count: level.index_count,
                    instance_count: 1,
                    first_index: level.first_index,
                    base_vertex: level.base_vertex,
                    first_instance: instance,
                }),
            }
        }
    }
}

/// A render pass into the id target `ids`, cleared to [`NO_OBJECT`], with the reverse-Z depth
/// buffer `depth` cleared to 0 (infinitely far).
fn begin_id_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    ids: &wgpu::TextureView,
    depth: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: ids,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                // NO_OBJECT = u32::MAX, exactly representable in the f64 clear value.
                load: wgpu::LoadOp::Clear(wgpu::Color { r: NO_OBJECT as f64, g: 0.0, b: 0.0, a: 0.0 }),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// `count` bind groups of `layout`, group `k` over the uniform block at `k` strides of `uniforms`.
fn face_bind_groups(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    uniforms: &wgpu::Buffer,
    count: usize,
) -> Vec<wgpu::BindGroup> {
    (0..count as u64)
        .map(|k| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("dov face"),
                layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: uniforms,
                        offset: k * UNIFORM_STRIDE,
                        size: wgpu::BufferSize::new(std::mem::size_of::<FaceUniform>() as u64),
                    }),
                }],
            })
        })
        .collect()
}

/// Every base mesh's levels, model space, in one position and one index buffer.
struct ModelGeometry {
    positions: Vec<[f32; 3]>,
    indices: Vec<u32>,
    levels: Vec<Vec<MeshLevel>>,
}

impl ModelGeometry {
    fn build(scene: &Scene, lods: Option<&[Vec<LodLevel>]>) -> Result<Self> {
        let mut out =
            Self { positions: Vec::new(), indices: Vec::new(), levels: Vec::with_capacity(scene.meshes.len()) };
        for (m, base) in scene.meshes.iter().enumerate() {
            let mut levels = vec![out.push(&base.mesh, 0.0)?];
            for level in lods.map_or(&[][..], |lods| lods[m].get(1..).unwrap_or(&[])) {
                levels.push(out.push(&level.mesh, level.error)?);
            }
            out.levels.push(levels);
        }
        Ok(out)
    }

    fn push(&mut self, mesh: &Mesh, error: f32) -> Result<MeshLevel> {
        let (base_vertex, first_index) = (self.positions.len(), self.indices.len());
        if base_vertex + mesh.positions.len() > i32::MAX as usize
            || first_index + mesh.indices.len() > u32::MAX as usize
        {
            return Err(Error::Gpu(format!(
                "{} vertices and {} indices exceed the GPU's index range",
                base_vertex + mesh.positions.len(),
                first_index + mesh.indices.len()
            )));
        }
        self.positions.extend_from_slice(&mesh.positions);
        self.indices.extend_from_slice(&mesh.indices);
        Ok(MeshLevel {
            first_index: first_index as u32,
            index_count: mesh.indices.len() as u32,
            base_vertex: base_vertex as i32,
            error,
        })
    }
}

/// The objects in draw (descending id) order with their world boxes relative to `origin`, taken
/// over the vertices every level's triangles use, each transformed as `Mat4::transform_point3`
/// and then offset (so the box, which LOD selection measures distance to, does not depend on
/// how the GPU composes the transform).
fn draw_objects(scene: &Scene, lods: Option<&[Vec<LodLevel>]>, origin: Vec3) -> Vec<DrawObject> {
    // Per base mesh, the positions its levels' triangles use, each once.
    let used: Vec<Vec<Vec3>> = scene
        .meshes
        .iter()
        .enumerate()
        .map(|(m, base)| {
            let coarser = lods.map_or(&[][..], |lods| lods[m].get(1..).unwrap_or(&[]));
            std::iter::once(&base.mesh).chain(coarser.iter().map(|l| &l.mesh)).flat_map(used_positions).collect()
        })
        .collect();
    (0..scene.objects.len())
        .rev()
        .map(|o| {
            let object = &scene.objects[o];
            let m = object.transform;
            let bounds =
                used[object.mesh as usize].iter().fold(Aabb::EMPTY, |b, &p| b.grow(m.transform_point3(p) - origin));
            let scale = max_scale(&m);
            DrawObject { mesh: object.mesh, scale, bounds }
        })
        .collect()
}

/// The positions `mesh`'s triangles refer to, each once.
fn used_positions(mesh: &Mesh) -> Vec<Vec3> {
    let mut seen = vec![false; mesh.positions.len()];
    let mut out = Vec::new();
    for &i in &mesh.indices {
        if let Some(s) = seen.get_mut(i as usize)
            && !*s
        {
            *s = true;
            out.push(Vec3::from(mesh.positions[i as usize]));
        }
    }
    out
}

fn create_pipeline(device: &wgpu::Device, bind_layout: &wgpu::BindGroupLayout) -> wgpu::RenderPipeline {
    let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("dov id cube"),
        source: wgpu::ShaderSource::Wgsl(include_str!("gpu.wgsl").into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("dov id cube"),
        bind_group_layouts: &[Some(bind_layout)],
        immediate_size: 0,
    });
    let buffers = [
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<[f32; 3]>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &POSITION_ATTRIBUTES,
        }),
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Instance>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &Instance::ATTRIBUTES,
        }),
    ];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("dov id cube"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &buffers,
        },
        // Back faces are visible surfaces too (and flagged); at equal depth the later draw
        // (lower id) wins.
        primitive: crate::gfx::two_sided_triangles(),
        depth_stencil: Some(crate::gfx::reverse_z_depth()),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: wgpu::TextureFormat::R32Uint,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The matrix taking `position − eye` to clip space for one face: x = right·d, y = up·d,
/// z = near, w = forward·d. So NDC (x, y) is the cube map's (u, v) and depth is `near/forward·d`
/// (reverse Z, 1 at the near plane, → 0 at infinity).
fn clip_from_rel(b: FaceBasis, near: f32) -> Mat4 {
    Mat4::from_cols(b.right.extend(0.0), b.up.extend(0.0), Vec4::new(0.0, 0.0, 0.0, near), b.forward.extend(0.0))
        .transpose()
}

impl DovBackend for GpuBackend {
    fn name(&self) -> String {
        match self.region_resolution {
            0 => format!("gpu ({})", self.gpu.adapter_name),
            r => format!("gpu ({}), region views of {r}² texels a face", self.gpu.adapter_name),
        }
    }

    fn resolution(&self) -> u32 {
        self.cube.resolution()
    }

    fn cube_map(&self) -> &CubeMap {
        &self.cube
    }

    fn region_views(&mut self, cell: &crate::grid::ViewCell, rays: u32) -> Option<Result<(RegionViews, Vec<u32>)>> {
        if self.region_resolution == 0 {
            return None;
        }
        let views = RegionViews::new(cell, rays, self.region_resolution);
        Some(self.draw_region_views(&views).map(|ids| (views, ids)))
    }

    fn render_ids(&mut self, p: Vec3, out: &mut IdCube) -> Result<()> {
        check_point(p)?;
        let r = self.cube.resolution();
        check_cube(out, r)?;
        let eye = p - self.origin;
        let validation = self.gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let chosen = self.chosen_levels(eye);
        for face in 0..FACE_COUNT {
            let u = FaceUniform {
                clip_from_rel: clip_from_rel(face_basis(face), self.near).to_cols_array_2d(),
                eye: eye.extend(0.0).to_array(),
            };
            self.gpu.queue.write_buffer(&self.uniforms, face as u64 * UNIFORM_STRIDE, bytemuck::bytes_of(&u));
        }
        // All six faces' commands in one list; face f's start at `starts[f]`.
        let mut commands = Vec::new();
        let mut starts = [0usize; FACE_COUNT + 1];
        for face in 0..FACE_COUNT {
            self.face_commands(face_basis(face), eye, &chosen, &mut commands);
            starts[face + 1] = commands.len();
        }
        self.count_drawn(&commands);
        if let Some(indirect) = &self.indirect
            && !commands.is_empty()
        {
            self.gpu.queue.write_buffer(indirect, 0, &command_bytes(&commands));
        }
        let mut encoder =
            self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("dov cube") });
        for face in 0..FACE_COUNT {
            let mut pass = begin_id_pass(&mut encoder, "dov face", &self.face_targets[face].1, &self.depth_view);
            let indirect = self.indirect.as_ref().map(|buffer| (buffer, starts[face]));
            self.issue(&mut pass, &self.face_bind_groups[face], &commands[starts[face]..starts[face + 1]], indirect);
        }
        for (face, (texture, _)) in self.face_targets.iter().enumerate() {
            let offset = face as u64 * self.padded_row_bytes as u64 * r as u64;
            copy_ids(&mut encoder, texture, (&self.readback, offset, self.padded_row_bytes), r, r);
        }
        self.gpu.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(Error::Gpu(format!("{}: rendering: {e}", self.gpu.adapter_name)));
        }
        self.read_back(out)
    }
}

/// The draw commands as the bytes of an indirect buffer.
fn command_bytes(commands: &[DrawIndexedIndirectArgs]) -> Vec<u8> {
    commands.iter().flat_map(|c| c.as_bytes().iter().copied()).collect()
}

/// Copies the top `width × height` texels of the id target `texture` into `to` = (buffer, byte
/// offset, padded bytes a row).
fn copy_ids(encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture, to: (&wgpu::Buffer, u64, u32), width: u32, height: u32) {
    let (buffer, offset, padded_row_bytes) = to;
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo { texture, mip_level: 0, origin: wgpu::Origin3d::ZERO, aspect: wgpu::TextureAspect::All },
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset,
                bytes_per_row: Some(padded_row_bytes),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
}

impl GpuBackend {
    /// Counts `commands` as drawn ([`GpuBackend::draw_commands`], [`GpuBackend::triangles_drawn`]).
    fn count_drawn(&mut self, commands: &[DrawIndexedIndirectArgs]) {
        self.draw_commands += commands.len() as u64;
        self.triangles_drawn +=
            commands.iter().map(|c| u64::from(c.index_count / 3) * u64::from(c.instance_count)).sum::<u64>();
    }

    /// Issues `commands` in `pass` with the face uniforms of `bind_group`: as one indirect
    /// multi-draw of the commands that start at command `first` of `indirect` where given, else
    /// as direct draws.
    fn issue(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        bind_group: &wgpu::BindGroup,
        commands: &[DrawIndexedIndirectArgs],
        indirect: Option<(&wgpu::Buffer, usize)>,
    ) {
        let Some(geometry) = &self.geometry else { return };
        if commands.is_empty() {
            return;
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_vertex_buffer(0, geometry.positions.slice(..));
        pass.set_vertex_buffer(1, geometry.instances.slice(..));
        pass.set_index_buffer(geometry.indices.slice(..), wgpu::IndexFormat::Uint32);
        match indirect {
            Some((buffer, first)) => {
                let offset = (first * std::mem::size_of::<DrawIndexedIndirectArgs>()) as u64;
                pass.multi_draw_indexed_indirect(buffer, offset, commands.len() as u32);
            }
            None => {
                for c in commands {
                    pass.draw_indexed(
                        c.first_index..c.first_index + c.index_count,
                        c.base_vertex,
                        c.first_instance..c.first_instance + c.instance_count,
                    );
                }
            }
        }
    }

    /// The region views' targets (see [`RegionTargets`]).
    fn region_targets(&self) -> RegionTargets {
        let r = self.region_resolution;
        let (width, height) = (r * FACE_COUNT as u32, REGION_ATLAS_ROWS / r * r);
        let atlas = self.gpu.target("dov region views", width, height, wgpu::TextureFormat::R32Uint);
        let atlas_view = atlas.create_view(&wgpu::TextureViewDescriptor::default());
        let depth = self.gpu.depth_buffer("dov region depth", width, height);
        let depth_view = depth.create_view(&wgpu::TextureViewDescriptor::default());
        let padded_row_bytes = crate::gfx::padded_row_bytes(width, 4);
        let readback = self.gpu.readback_buffer("dov region readback", padded_row_bytes as u64 * height as u64);
        let slots = (REGION_ATLAS_ROWS / r) as usize * FACE_COUNT;
        let uniforms = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("dov region uniforms"),
            size: UNIFORM_STRIDE * slots as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_groups = face_bind_groups(&self.gpu.device, &self.bind_layout, &uniforms, slots);
        RegionTargets { atlas, atlas_view, depth_view, readback, padded_row_bytes, uniforms, bind_groups, indirect: None }
    }

    /// [`DovBackend::region_views`]: as many views a render pass as fill [`REGION_ATLAS_ROWS`],
    /// each face into its square of the atlas (a viewport), objects culled per face by their
    /// boxes as for a whole cube map, one copy and one blocking read-back a pass.
    fn draw_region_views(&mut self, views: &RegionViews) -> Result<Vec<u32>> {
        for &(origin, _) in views.views() {
            check_point(origin)?;
        }
        let mut out = vec![NO_OBJECT; views.texel_count()];
        if self.geometry.is_none() {
            return Ok(out);
        }
        if self.region.is_none() {
            self.region = Some(self.region_targets());
        }
        let r = self.region_resolution;
        let batch_views = (REGION_ATLAS_ROWS / r) as usize;
        let per_view = views.cube().texel_count();
        for (batch, chunk) in views.views().chunks(batch_views).enumerate() {
            let validation = self.gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
            // Each face of each view: its uniforms and draw commands; slot `s` = view · 6 + face.
            let mut commands = Vec::new();
            let mut starts = vec![0usize; chunk.len() * FACE_COUNT + 1];
            for (v, &(origin, turn)) in chunk.iter().enumerate() {
                let eye = origin - self.origin;
                let chosen = self.chosen_levels(eye);
                for face in 0..FACE_COUNT {
                    let slot = v * FACE_COUNT + face;
                    let basis = face_basis(face).turned(turn);
                    let u = FaceUniform {
                        clip_from_rel: clip_from_rel(basis, self.near).to_cols_array_2d(),
                        eye: eye.extend(0.0).to_array(),
                    };
                    let region = self.region.as_ref().expect("made above");
                    self.gpu.queue.write_buffer(&region.uniforms, slot as u64 * UNIFORM_STRIDE, bytemuck::bytes_of(&u));
                    self.face_commands(basis, eye, &chosen, &mut commands);
                    starts[slot + 1] = commands.len();
                }
            }
            self.count_drawn(&commands);
            if self.indirect.is_some() && !commands.is_empty() {
                let bytes = command_bytes(&commands);
                let region = self.region.as_mut().expect("made above");
                if region.indirect.as_ref().is_none_or(|b| b.size() < bytes.len() as u64) {
                    region.indirect = Some(self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("dov region draw commands"),
                        size: (bytes.len() as u64).next_power_of_two(),
                        usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    }));
                }
                self.gpu.queue.write_buffer(region.indirect.as_ref().expect("made above"), 0, &bytes);
            }
            let region = self.region.as_ref().expect("made above");
            let mut encoder =
                self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("dov region") });
            {
                let mut pass = begin_id_pass(&mut encoder, "dov region views", &region.atlas_view, &region.depth_view);
                for slot in 0..chunk.len() * FACE_COUNT {
                    let (x, y) = ((slot % FACE_COUNT) as u32 * r, (slot / FACE_COUNT) as u32 * r);
                    pass.set_viewport(x as f32, y as f32, r as f32, r as f32, 0.0, 1.0);
                    pass.set_scissor_rect(x, y, r, r);
                    // The region's command buffer exists only where the device draws indirectly.
                    let indirect = region.indirect.as_ref().map(|b| (b, starts[slot]));
                    self.issue(&mut pass, &region.bind_groups[slot], &commands[starts[slot]..starts[slot + 1]], indirect);
                }
            }
            let rows = chunk.len() as u32 * r;
            copy_ids(&mut encoder, &region.atlas, (&region.readback, 0, region.padded_row_bytes), r * FACE_COUNT as u32, rows);
            self.gpu.queue.submit([encoder.finish()]);
            if let Some(e) = pollster::block_on(validation.pop()) {
                return Err(Error::Gpu(format!("{}: drawing region views: {e}", self.gpu.adapter_name)));
            }
            let first = batch * batch_views * per_view;
            let (r, faces) = (r as usize, FACE_COUNT);
            self.gpu.read_buffer(&region.readback, |data| {
                for (y, row) in data.chunks_exact(region.padded_row_bytes as usize).take(rows as usize).enumerate() {
                    let (v, texel_row) = (y / r, y % r);
                    for (x, s) in row[..faces * r * 4].chunks_exact(4).enumerate() {
                        let (face, col) = (x / r, x % r);
                        out[first + v * per_view + face * r * r + texel_row * r + col] =
                            u32::from_le_bytes([s[0], s[1], s[2], s[3]]);
                    }
                }
            })?;
        }
        Ok(out)
    }

    /// Maps the read-back buffer (blocking until the GPU is done) and strips the row padding.
    fn read_back(&self, out: &mut IdCube) -> Result<()> {
        let r = self.cube.resolution() as usize;
        let row_bytes = r * 4;
        self.gpu.read_buffer(&self.readback, |data| {
            for (dst, src) in out.ids.chunks_exact_mut(r).zip(data.chunks_exact(self.padded_row_bytes as usize)) {
                for (d, s) in dst.iter_mut().zip(src[..row_bytes].chunks_exact(4)) {
                    *d = u32::from_le_bytes([s[0], s[1], s[2], s[3]]);
                }
            }
        })
    }
}
