//! The GPU backend: wgpu rasterisation of the id cube map.
//!
//! All geometry is uploaded once, in world space relative to the scene's centre (f32 precision
//! stays near the geometry), one vertex = position + object id. Objects lie in the vertex buffer in
//! *descending* id order, so that (a) the objects that survive a face's frustum test form a few
//! contiguous vertex ranges, one draw each, and (b) with a `GreaterEqual` reverse-Z depth test,
//! the later-drawn lower id wins an exact depth tie — the CPU backend's tie rule.
//!
//! Each face is rendered into its own R32Uint 2D texture (copying 2D-array layers to a buffer
//! reads back zeros on the GL backend), then all six are copied into one mapped buffer and
//! weighed on the CPU with [`super::IdCube::dov`], exactly as the CPU backend's ids are.
//!
//! **LOD-aware drawing** ([`GpuBackend::with_options`] with [`GpuOptions::lods`]): every coarser
//! leaf LOD of every object is uploaded too, in world space right after the object's full-detail
//! triangles, and per sample point each object is drawn at the coarsest level whose world-space
//! error, seen from the point at the distance of the object's box, subtends less than
//! [`GpuOptions::lod_tolerance_texels`] texels at the face centre (a texel there spans 2/R
//! radians). An object whose box contains the point is drawn at full detail. docs/dov.md
//! ("LOD-aware drawing") has the measured DoV change and speed-up.

use glam::{Mat4, Vec3, Vec4};

use super::cpu::{check_cube, check_point, check_resolution_and_near, world_triangles};
use super::cubemap::{FACE_COUNT, face_basis};
use super::{CubeMap, DovBackend, IdCube};
use crate::error::{Error, Result};
use crate::geom::Aabb;
use crate::gfx::{Gpu, Vertex, push_world};
use crate::lod::LodLevel;
use crate::scene::Scene;

/// Bytes between the six per-face uniform blocks (the largest `min_uniform_buffer_offset_alignment`
/// wgpu allows).
const UNIFORM_STRIDE: u64 = 256;

/// Default of [`GpuOptions::lod_tolerance_texels`]: a twentieth of a texel at the face centre.
/// Half a texel (the first guess) changes some objects' DoV by up to 10 centre texels on a
/// generated city, because the simplifier's error is not a bound on silhouette movement and a
/// shifted silhouette changes an area in proportion to its length; 0.05 keeps every object within
/// the backends' agreement tolerance (0.5 % of its DoV + 2 centre texels) at R = 128 and 256
/// (docs/dov.md, "LOD-aware drawing").
pub const DEFAULT_LOD_TOLERANCE_TEXELS: f32 = 0.05;

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
}

impl Default for GpuOptions<'_> {
    fn default() -> Self {
        Self { near: None, lods: None, lod_tolerance_texels: DEFAULT_LOD_TOLERANCE_TEXELS }
    }
}

pub use crate::gfx::{REQUIRE_ADAPTER_ENV, adapter_available, adapter_or_skip, hardware_adapter_available};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FaceUniform {
    clip_from_rel: [[f32; 4]; 4],
    eye: [f32; 4],
}

/// Rasterises the id cube around a point with wgpu. Construction uploads all geometry once and
/// allocates the render targets; each [`DovBackend::render_ids`] does 6 render passes (objects
/// culled per face by their boxes), one copy and one blocking read-back of 6·R²·4 bytes.
pub struct GpuBackend {
    cube: CubeMap,
    near: f32,
    gpu: Gpu,
    pipeline: wgpu::RenderPipeline,
    uniforms: wgpu::Buffer,
    face_bind_groups: Vec<wgpu::BindGroup>,
    vertices: Option<wgpu::Buffer>,
    /// Per object in draw (descending id) order, its levels finest first: the vertex range in
    /// the vertex buffer and the world-space error (0 for full detail).
    draw_levels: Vec<Vec<LevelRange>>,
    /// Largest world error / distance drawn at a coarser level (radians); 0 without LODs.
    lod_max_angle: f32,
    /// Triangles drawn since construction, over all faces and points.
    triangles_drawn: u64,
    /// Bounds of each object in draw order, relative to `origin`.
    draw_bounds: Vec<Aabb>,
    origin: Vec3,
    face_targets: Vec<(wgpu::Texture, wgpu::TextureView)>,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row_bytes: u32,
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

    /// As [`GpuBackend::new`] with [`GpuOptions`]: near plane and LOD-aware drawing. With
    /// `options.lods`, every coarser level of every object is uploaded as well (world space, so
    /// GPU memory grows by the coarser levels' triangles: at most about as much again as the
    /// scene for ratio ½, +29 % on the small generated city).
    /// Fails with [`Error::BadParam`] when `lods` has not one chain per base mesh
    /// or the tolerance is negative or not finite.
    pub fn with_options(scene: &Scene, resolution: u32, options: &GpuOptions) -> Result<Self> {
        let near = options.near.unwrap_or_else(|| super::default_near(&scene.bounds()));
        check_resolution_and_near(resolution, near)?;
        let tolerance = options.lod_tolerance_texels;
        if !(tolerance.is_finite() && tolerance >= 0.0) {
            return Err(Error::bad_param("LOD tolerance", format!("{tolerance} must be finite and >= 0")));
        }
        if let Some(lods) = options.lods
            && lods.len() != scene.meshes.len()
        {
            return Err(Error::bad_param(
                "LODs",
                format!("{} chains for {} base meshes", lods.len(), scene.meshes.len()),
            ));
        }
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
        let geometry = Geometry::build(scene, origin, options.lods)?;
        let vertices = gpu.upload_vertices("dov vertices", &geometry.vertices)?;

        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("dov face uniforms"),
            size: UNIFORM_STRIDE * FACE_COUNT as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_layout = crate::gfx::uniform_layout::<FaceUniform>(device, "dov face", wgpu::ShaderStages::VERTEX);
        let face_bind_groups = (0..FACE_COUNT as u64)
            .map(|f| {
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("dov face"),
                    layout: &bind_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &uniforms,
                            offset: f * UNIFORM_STRIDE,
                            size: wgpu::BufferSize::new(std::mem::size_of::<FaceUniform>() as u64),
                        }),
                    }],
                })
            })
            .collect();
        let pipeline = create_pipeline(device, &bind_layout);

        let extent = wgpu::Extent3d { width: resolution, height: resolution, depth_or_array_layers: 1 };
        let face_targets = (0..FACE_COUNT)
            .map(|_| {
                let texture = device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("dov id face"),
                    size: extent,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::R32Uint,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
                (texture, view)
            })
            .collect();
        let depth = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("dov depth"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Depth32Float,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        });
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
            face_bind_groups,
            vertices,
            draw_levels: geometry.draw_levels,
            lod_max_angle: if options.lods.is_some() { tolerance * 2.0 / resolution as f32 } else { 0.0 },
            triangles_drawn: 0,
            draw_bounds: geometry.draw_bounds,
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

    /// Whether LOD-aware drawing is on (LODs given and a tolerance above 0).
    pub fn lod_drawing(&self) -> bool {
        self.lod_max_angle > 0.0
    }

    /// Per object in draw order, the vertex range of the level to draw from `eye`: the coarsest
    /// whose world error / distance to the object's box is below the tolerance angle; full
    /// detail when the box contains the eye.
    fn chosen_ranges(&self, eye: Vec3) -> Vec<std::ops::Range<u32>> {
        self.draw_levels
            .iter()
            .zip(&self.draw_bounds)
            .map(|(levels, bounds)| {
                if levels.len() == 1 || self.lod_max_angle <= 0.0 {
                    return levels[0].vertices.clone();
                }
                // Distance from the eye to the box (0 inside it, so full detail there).
                let distance = (bounds.min - eye).max(eye - bounds.max).max(Vec3::ZERO).length();
                let budget = self.lod_max_angle * distance;
                levels
                    .iter()
                    .rev()
                    .find(|l| l.error < budget)
                    .map_or_else(|| levels[0].vertices.clone(), |l| l.vertices.clone())
            })
            .collect()
    }

    /// Vertex ranges to draw for one face: objects whose box may reach into the face's frustum,
    /// at the levels in `chosen` (one range per object in draw order), consecutive ones merged.
    /// Conservative: a box is dropped only when it lies wholly outside one of the frustum's
    /// planes (or wholly nearer than the near plane).
    fn visible_ranges(&self, face: usize, eye: Vec3, chosen: &[std::ops::Range<u32>]) -> Vec<std::ops::Range<u32>> {
        let b = face_basis(face);
        // Inside the frustum: n·d ≥ 0 for each side normal, forward·d ≥ near.
        let sides = [b.forward - b.right, b.forward + b.right, b.forward - b.up, b.forward + b.up];
        let mut ranges: Vec<std::ops::Range<u32>> = Vec::new();
        for (range, bounds) in chosen.iter().zip(&self.draw_bounds) {
            if range.is_empty() {
                continue;
            }
            let centre = bounds.center() - eye;
            let half = bounds.extent() * 0.5;
            // The box's largest value of n·d; slack covers rounding at the planes.
            let reach = |n: Vec3| n.dot(centre) + n.abs().dot(half);
            let slack = 1e-5 * (centre.length() + half.length());
            let outside = sides.iter().any(|&n| reach(n) < -slack) || reach(b.forward) < self.near - slack;
            if outside {
                continue;
            }
            match ranges.last_mut() {
                Some(last) if last.end == range.start => last.end = range.end,
                _ => ranges.push(range.clone()),
            }
        }
        ranges
    }
}

/// One level of one object in the vertex buffer.
#[derive(Clone, Debug)]
struct LevelRange {
    vertices: std::ops::Range<u32>,
    /// The simplifier's error scaled to world units by the transform's largest axis scale.
    error: f32,
}

/// The scene as one vertex buffer (three vertices per triangle, no sharing: every object is its
/// own world-space copy), objects in descending id order, each object's full detail followed by
/// its coarser LODs (when given).
struct Geometry {
    vertices: Vec<Vertex>,
    draw_levels: Vec<Vec<LevelRange>>,
    draw_bounds: Vec<Aabb>,
}

impl Geometry {
    fn build(scene: &Scene, origin: Vec3, lods: Option<&[Vec<LodLevel>]>) -> Result<Self> {
        let (triangles, objects) = world_triangles(scene)?;
        // Triangles are grouped by object in ascending order; walk the groups backwards.
        let mut starts = vec![0usize; scene.objects.len() + 1];
        for &o in &objects {
            starts[o as usize + 1] += 1;
        }
        for i in 1..starts.len() {
            starts[i] += starts[i - 1];
        }
        let extra: usize = lods.map_or(0, |lods| {
            scene.objects.iter().map(|o| lods[o.mesh as usize].iter().skip(1).map(|l| l.faces()).sum::<usize>()).sum()
        });
        let mut vertices = Vec::with_capacity((triangles.len() + extra) * 3);
        let mut draw_levels = Vec::with_capacity(scene.objects.len());
        let mut draw_bounds = Vec::with_capacity(scene.objects.len());
        for object in (0..scene.objects.len()).rev() {
            let first = vertices.len() as u32;
            let mut bounds = Aabb::EMPTY;
            for t in &triangles[starts[object]..starts[object + 1]] {
                for p in t {
                    let rel = *p - origin;
                    bounds = bounds.grow(rel);
                    vertices.push(Vertex { position: rel.to_array(), id: object as u32 });
                }
            }
            let mut levels = vec![LevelRange { vertices: first..vertices.len() as u32, error: 0.0 }];
            if let Some(lods) = lods {
                let o = &scene.objects[object];
                let m = o.transform;
                let scale =
                    m.x_axis.truncate().length().max(m.y_axis.truncate().length()).max(m.z_axis.truncate().length());
                for level in lods[o.mesh as usize].iter().skip(1) {
                    let first = vertices.len() as u32;
                    push_world(&mut vertices, &level.mesh, &m, origin, object as u32);
                    // Culling must keep a coarse level that bulges out of the full-detail box.
                    for v in &vertices[first as usize..] {
                        bounds = bounds.grow(Vec3::from(v.position));
                    }
                    levels.push(LevelRange { vertices: first..vertices.len() as u32, error: level.error * scale });
                }
            }
            draw_levels.push(levels);
            draw_bounds.push(bounds);
            if vertices.len() > u32::MAX as usize {
                return Err(Error::Gpu(format!("{} vertices exceed u32 vertex indices", vertices.len())));
            }
        }
        Ok(Self { vertices, draw_levels, draw_bounds })
    }
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
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("dov id cube"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(Vertex::layout())],
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
fn clip_from_rel(face: usize, near: f32) -> Mat4 {
    let b = face_basis(face);
    Mat4::from_cols(b.right.extend(0.0), b.up.extend(0.0), Vec4::new(0.0, 0.0, 0.0, near), b.forward.extend(0.0))
        .transpose()
}

impl DovBackend for GpuBackend {
    fn name(&self) -> String {
        format!("gpu ({})", self.gpu.adapter_name)
    }

    fn resolution(&self) -> u32 {
        self.cube.resolution()
    }

    fn cube_map(&self) -> &CubeMap {
        &self.cube
    }

    fn render_ids(&mut self, p: Vec3, out: &mut IdCube) -> Result<()> {
        check_point(p)?;
        let r = self.cube.resolution();
        check_cube(out, r)?;
        let eye = p - self.origin;
        let validation = self.gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let chosen = self.chosen_ranges(eye);
        for face in 0..FACE_COUNT {
            let u = FaceUniform {
                clip_from_rel: clip_from_rel(face, self.near).to_cols_array_2d(),
                eye: eye.extend(0.0).to_array(),
            };
            self.gpu.queue.write_buffer(&self.uniforms, face as u64 * UNIFORM_STRIDE, bytemuck::bytes_of(&u));
        }
        let mut encoder =
            self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("dov cube") });
        for face in 0..FACE_COUNT {
            let ranges = self.visible_ranges(face, eye, &chosen);
            self.triangles_drawn += ranges.iter().map(|r| r.len() as u64 / 3).sum::<u64>();
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("dov face"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.face_targets[face].1,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        // NO_OBJECT = u32::MAX, exactly representable in the f64 clear value.
                        load: wgpu::LoadOp::Clear(wgpu::Color { r: u32::MAX as f64, g: 0.0, b: 0.0, a: 0.0 }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let Some(vertices) = &self.vertices
                && !ranges.is_empty()
            {
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.face_bind_groups[face], &[]);
                pass.set_vertex_buffer(0, vertices.slice(..));
                for range in ranges {
                    pass.draw(range, 0..1);
                }
            }
        }
        for (face, (texture, _)) in self.face_targets.iter().enumerate() {
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: &self.readback,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: face as u64 * self.padded_row_bytes as u64 * r as u64,
                        bytes_per_row: Some(self.padded_row_bytes),
                        rows_per_image: Some(r),
                    },
                },
                wgpu::Extent3d { width: r, height: r, depth_or_array_layers: 1 },
            );
        }
        self.gpu.queue.submit([encoder.finish()]);
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(Error::Gpu(format!("{}: rendering: {e}", self.gpu.adapter_name)));
        }
        self.read_back(out)
    }
}

impl GpuBackend {
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
