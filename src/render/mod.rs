//! Offscreen views of a database: the full-detail scene (every object at LOD 0 under its
//! transform) or a query's [`Answer`] (objects and internal LODs at their chosen levels), drawn
//! with wgpu from a [`View`] into an RGBA8 image, a depth buffer and an item-id (coverage)
//! buffer, all read back to the CPU; [`fidelity`] compares two such images.
//!
//! Shading is Lambert from the face normal (computed per fragment from screen-space
//! derivatives of the position, turned towards the eye) with a fixed light and a little ambient,
//! so that a simplified shape shows as a change of shade. [`ColorMode`] picks the base colour.
//! The device set-up, vertex format and read-back are [`crate::gfx`]'s, shared with the DoV GPU
//! backend.

pub mod fidelity;

use std::collections::HashMap;
use std::path::Path;

use glam::{Mat4, Vec3};

use crate::camera::{Camera, Frustum};
use crate::db::Database;
use crate::error::{Error, Param, Result};
use crate::format::catalog::LodRef;
use crate::gfx::{Gpu, Vertex, padded_row_bytes, push_world};
use crate::query::{Answer, Item, ItemKind, Session};
use crate::scene::Mesh;

/// [`Image::ids`] where nothing was drawn.
pub const NO_ITEM: u32 = u32::MAX;

/// The RGB of pixels where nothing was drawn.
pub const BACKGROUND: [u8; 3] = [214, 228, 240];

/// Direction towards the fixed light (world space, y up; normalised when used): high, from +x
/// and a little +z, so that the four sides of a box show three shades.
pub const LIGHT: Vec3 = Vec3::new(0.5, 0.75, 0.3);

/// Shade = `AMBIENT + (1 − AMBIENT) · max(n · light, 0)` times the base colour.
pub const AMBIENT: f32 = 0.35;

/// A pinhole camera: where it is, where it looks (y up), its vertical field of view and image
/// size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Where the camera is.
    pub eye: Vec3,
    /// View direction (need not be unit length; not zero).
    pub look: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Near plane distance (there is no far plane).
    pub near: f32,
}

impl View {
    /// A view with the default near plane (0.05).
    pub fn new(eye: Vec3, look: Vec3, fov_y_deg: f32, width: u32, height: u32) -> View {
        View { eye, look, fov_y_deg, width, height, near: 0.05 }
    }

    /// The query camera of this view: the frustum a query culls its answer to.
    pub fn camera(&self) -> Camera {
        Camera {
            look: self.look,
            fov_y_deg: self.fov_y_deg,
            aspect: self.width as f32 / self.height as f32,
            image_height: self.height,
        }
    }

    /// A frustum a little wider than the image's (2 % in each direction): what lies outside it
    /// draws no pixel, so [`Renderer::draw`] skips it; the margin keeps rounding from culling a
    /// box that touches the image's edge.
    pub fn culling_frustum(&self) -> Frustum {
        let fov_y_deg = ((self.fov_y_deg.to_radians() / 2.0).tan() * 1.02).atan().to_degrees() * 2.0;
        Camera { fov_y_deg, ..self.camera() }.frustum(self.eye)
    }

    /// Checks the numbers; the error names the parameter.
    pub fn check(&self) -> Result<()> {
        if !self.eye.is_finite() {
            return Err(Error::bad_param(Param::At, format!("{:?} is not a finite point", self.eye.to_array())));
        }
        if self.width == 0 || self.height == 0 {
            return Err(Error::bad_param(Param::Size, format!("{}×{} has no pixels", self.width, self.height)));
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return Err(Error::bad_param(Param::Near, format!("{} must be finite and > 0", self.near)));
        }
        self.camera().check().map_err(|r| Error::bad_param(Param::Camera, r))
    }

    /// Unit forward, right and up vectors ([`crate::camera::basis`], as [`Camera::frustum`]).
    pub fn basis(&self) -> (Vec3, Vec3, Vec3) {
        crate::camera::basis(self.look)
    }

    /// The matrix taking `position − eye` to clip space: reverse Z (depth 1 at the near plane,
    /// → 0 at infinity).
    pub fn clip_from_rel(&self) -> Mat4 {
        let (forward, right, up) = self.basis();
        let f = 1.0 / (self.fov_y_deg.to_radians() / 2.0).tan();
        let aspect = self.width as f32 / self.height as f32;
        // Rows: x = f/aspect · right·d, y = f · up·d, z = near, w = forward·d.
        Mat4::from_cols(
            (right * f / aspect).extend(0.0),
            (up * f).extend(0.0),
            glam::Vec4::new(0.0, 0.0, 0.0, self.near),
            forward.extend(0.0),
        )
        .transpose()
    }

    /// Where `p` lands in the image, in pixels (x right, y down, pixel centres at .5), or `None`
    /// when it lies behind the near plane.
    pub fn project(&self, p: Vec3) -> Option<(f32, f32)> {
        let c = self.clip_from_rel() * (p - self.eye).extend(1.0);
        if c.w <= self.near * 0.5 {
            return None;
        }
        let (x, y) = (c.x / c.w, c.y / c.w);
        Some(((x + 1.0) * 0.5 * self.width as f32, (1.0 - y) * 0.5 * self.height as f32))
    }
}

/// How items are coloured before shading.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ColorMode {
    /// One light grey for everything: differences are shape only.
    #[default]
    Shaded,
    /// A ramp over log₁₀ DoV from 10⁻⁶ (dark blue) to 0.5 (yellow); grey where no DoV is known
    /// (the full-detail scene).
    Dov,
    /// Objects by LOD level ([`LOD_PALETTE`], level 0 blue); internal LODs magenta.
    Lod,
}

impl ColorMode {
    /// Every colour mode.
    pub const ALL: [ColorMode; 3] = [ColorMode::Shaded, ColorMode::Dov, ColorMode::Lod];

    /// The mode's name, as `--color` takes it.
    pub fn name(self) -> &'static str {
        match self {
            ColorMode::Shaded => "shaded",
            ColorMode::Dov => "dov",
            ColorMode::Lod => "lod",
        }
    }
}

hdov_storage::named!(ColorMode, "colour mode");
hdov_storage::by_names!(ColorMode);

/// The grey of [`ColorMode::Shaded`].
pub const GREY: [u8; 3] = [200, 200, 200];

/// Colours of object LOD levels 0, 1, 2, ... (repeating past the end).
pub const LOD_PALETTE: [[u8; 3]; 8] = [
    [66, 133, 244],
    [52, 168, 83],
    [251, 188, 5],
    [234, 67, 53],
    [0, 172, 193],
    [255, 112, 67],
    [158, 157, 36],
    [121, 85, 72],
];

/// The colour of internal LODs in [`ColorMode::Lod`].
pub const NODE_COLOR: [u8; 3] = [214, 96, 214];

/// The base colour of one item.
pub fn item_color(mode: ColorMode, kind: ItemKind, lod: u32, dov: Option<f32>) -> [u8; 3] {
    match mode {
        ColorMode::Shaded => GREY,
        ColorMode::Lod if kind == ItemKind::Node => NODE_COLOR,
        ColorMode::Lod => LOD_PALETTE[lod as usize % LOD_PALETTE.len()],
        ColorMode::Dov => match dov {
            None => GREY,
            Some(d) => dov_ramp(d),
        },
    }
}

/// The DoV colour ramp: log₁₀ DoV from −6 to log₁₀ 0.5, dark blue → teal → yellow.
pub fn dov_ramp(dov: f32) -> [u8; 3] {
    let lo = -6.0f32;
    let hi = 0.5f32.log10();
    let t = if dov > 0.0 { ((dov.log10() - lo) / (hi - lo)).clamp(0.0, 1.0) } else { 0.0 };
    let stops = [[40.0, 30.0, 120.0], [30.0, 160.0, 140.0], [250.0, 230.0, 40.0]];
    let (a, b, u) = if t < 0.5 { (stops[0], stops[1], t * 2.0) } else { (stops[1], stops[2], t * 2.0 - 1.0) };
    [0, 1, 2].map(|c| (a[c] + (b[c] - a[c]) * u).round() as u8)
}

/// One thing to draw: a mesh under a transform, in a base colour.
#[derive(Clone, Copy, Debug)]
pub struct Drawable<'a> {
    /// The mesh to draw.
    pub mesh: &'a Mesh,
    /// Its model-to-world transform.
    pub transform: Mat4,
    /// Its base colour.
    pub color: [u8; 3],
}

/// What a view drew, read back: row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA8, 4 bytes per pixel (alpha 255).
    pub rgba: Vec<u8>,
    /// Depth along the view direction of the nearest surface; 0 where nothing was drawn.
    pub depth: Vec<f32>,
    /// Index of the nearest drawable (in the order drawn), [`NO_ITEM`] where nothing was drawn.
    pub ids: Vec<u32>,
}

impl Image {
    fn index(&self, x: u32, y: u32) -> usize {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}×{}", self.width, self.height);
        (y * self.width + x) as usize
    }

    /// Whether anything covers pixel (x, y).
    pub fn covered(&self, x: u32, y: u32) -> bool {
        self.ids[self.index(x, y)] != NO_ITEM
    }

    /// The drawable covering pixel (x, y), or [`NO_ITEM`].
    pub fn id(&self, x: u32, y: u32) -> u32 {
        self.ids[self.index(x, y)]
    }

    /// The RGB of pixel (`x`, `y`).
    pub fn rgb(&self, x: u32, y: u32) -> [u8; 3] {
        let i = self.index(x, y) * 4;
        [self.rgba[i], self.rgba[i + 1], self.rgba[i + 2]]
    }

    /// Share of pixels covered.
    pub fn coverage(&self) -> f64 {
        self.ids.iter().filter(|&&i| i != NO_ITEM).count() as f64 / self.ids.len().max(1) as f64
    }

    /// `self` and `right` side by side (heights must agree), with a 4-pixel white gap.
    pub fn beside(&self, right: &Image) -> Image {
        assert_eq!(self.height, right.height, "images beside each other need one height");
        let gap = 4;
        let width = self.width + gap + right.width;
        let n = (width * self.height) as usize;
        let mut out =
            Image { width, height: self.height, rgba: vec![255; n * 4], depth: vec![0.0; n], ids: vec![NO_ITEM; n] };
        for y in 0..self.height {
            for (img, x0) in [(self, 0), (right, self.width + gap)] {
                let src = (y * img.width) as usize;
                let dst = (y * width + x0) as usize;
                let w = img.width as usize;
                out.rgba[dst * 4..(dst + w) * 4].copy_from_slice(&img.rgba[src * 4..(src + w) * 4]);
                out.depth[dst..dst + w].copy_from_slice(&img.depth[src..src + w]);
                out.ids[dst..dst + w].copy_from_slice(&img.ids[src..src + w]);
            }
        }
        out
    }

    /// Writes the RGBA image as a PNG file.
    pub fn write_png(&self, path: &Path) -> Result<()> {
        let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
        let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), self.width, self.height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Best);
        let fail = |e: png::EncodingError| Error::bad_file(path, format!("writing PNG: {e}"));
        let mut writer = encoder.write_header().map_err(fail)?;
        writer.write_image_data(&self.rgba).map_err(fail)?;
        writer.finish().map_err(fail)
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ViewUniform {
    clip_from_rel: [[f32; 4]; 4],
    light: [f32; 4],
    forward: [f32; 4],
}

const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
/// The view depth's target holds the f32's bits as a u32: 32-bit float colour targets are not
/// renderable on every adapter (GL through Mesa's llvmpipe refuses R32Float), 32-bit integer
/// ones are, and the bits read back are the same (docs/decisions.md, 71).
const DEPTH_OUT_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;

/// The offscreen renderer: a device and a pipeline; each view uploads its geometry, draws it
/// and reads the three targets back.
pub struct Renderer {
    gpu: Gpu,
    pipeline: wgpu::RenderPipeline,
    bind_layout: wgpu::BindGroupLayout,
}

impl Renderer {
    /// Opens the adapter (fails with [`Error::Gpu`] without one) and builds the pipeline.
    pub fn new() -> Result<Renderer> {
        let gpu = Gpu::open("hdov render")?;
        let device = &gpu.device;
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let bind_layout =
            crate::gfx::uniform_layout::<ViewUniform>(device, "render view", wgpu::ShaderStages::VERTEX_FRAGMENT);
        let pipeline = create_pipeline(device, &bind_layout);
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(Error::Gpu(format!("{}: setting up the renderer: {e}", gpu.adapter_name)));
        }
        Ok(Renderer { gpu, pipeline, bind_layout })
    }

    /// The adapter's name, driver and backend.
    pub fn adapter_name(&self) -> &str {
        &self.gpu.adapter_name
    }

    /// Draws `items` from `view`; [`Image::ids`] holds indices into `items`. Where two surfaces
    /// lie at exactly the same depth the later item wins.
    pub fn draw(&self, items: &[Drawable], view: &View) -> Result<Image> {
        view.check()?;
        let (w, h) = (view.width, view.height);
        self.gpu.check_texture_size("image", w, h)?;
        let mut vertices = Vec::new();
        let mut colors = Vec::new();
        let frustum = view.culling_frustum();
        for (i, d) in items.iter().enumerate() {
            if !frustum.meets(&d.mesh.bounds().transformed(&d.transform)) {
                continue;
            }
            let first = vertices.len();
            push_world(&mut vertices, d.mesh, &d.transform, view.eye, i as u32);
            let c = u32::from_le_bytes([d.color[0], d.color[1], d.color[2], 255]);
            colors.resize(colors.len() + vertices.len() - first, c);
        }
        let device = &self.gpu.device;
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out_of_memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let vertex_buffer = self.gpu.upload_vertices("render vertices", &vertices)?;
        let color_buffer = (!colors.is_empty()).then(|| {
            use wgpu::util::DeviceExt;
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("render colours"),
                contents: bytemuck::cast_slice(&colors),
                usage: wgpu::BufferUsages::VERTEX,
            })
        });
        let (forward, _, _) = view.basis();
        let uniform = ViewUniform {
            clip_from_rel: view.clip_from_rel().to_cols_array_2d(),
            light: LIGHT.normalize().extend(AMBIENT).to_array(),
            forward: forward.extend(0.0).to_array(),
        };
        let uniforms = {
            use wgpu::util::DeviceExt;
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("render view"),
                contents: bytemuck::bytes_of(&uniform),
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render view"),
            layout: &self.bind_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: uniforms.as_entire_binding() }],
        });
        let color = self.gpu.target("render colour", w, h, COLOR_FORMAT);
        let ids = self.gpu.target("render ids", w, h, ID_FORMAT);
        let depth_out = self.gpu.target("render depth out", w, h, DEPTH_OUT_FORMAT);
        let depth = self.gpu.depth_buffer("render depth", w, h);
        let views: Vec<wgpu::TextureView> =
            [&color, &ids, &depth_out, &depth].iter().map(|t| t.create_view(&Default::default())).collect();
        let row = padded_row_bytes(w, 4);
        let target_bytes = row as u64 * h as u64;
        let readback = self.gpu.readback_buffer("render readback", target_bytes * 3);
        let bg = BACKGROUND.map(|c| c as f64 / 255.0);
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("render") });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("render"),
                color_attachments: &[
                    attachment(&views[0], wgpu::Color { r: bg[0], g: bg[1], b: bg[2], a: 1.0 }),
                    // NO_ITEM = u32::MAX, exactly representable in the f64 clear value.
                    attachment(&views[1], wgpu::Color { r: NO_ITEM as f64, g: 0.0, b: 0.0, a: 0.0 }),
                    attachment(&views[2], wgpu::Color::TRANSPARENT),
                ],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &views[3],
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let (Some(v), Some(c)) = (&vertex_buffer, &color_buffer) {
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.set_vertex_buffer(0, v.slice(..));
                pass.set_vertex_buffer(1, c.slice(..));
                pass.draw(0..vertices.len() as u32, 0..1);
            }
        }
        for (k, texture) in [&color, &ids, &depth_out].into_iter().enumerate() {
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer: &readback,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: k as u64 * target_bytes,
                        bytes_per_row: Some(row),
                        rows_per_image: Some(h),
                    },
                },
                wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            );
        }
        self.gpu.queue.submit([encoder.finish()]);
        for scope in [out_of_memory, validation] {
            if let Some(e) = pollster::block_on(scope.pop()) {
                return Err(Error::Gpu(format!("{}: rendering: {e}", self.gpu.adapter_name)));
            }
        }
        let n = (w * h) as usize;
        let mut image = Image {
            width: w,
            height: h,
            rgba: Vec::with_capacity(n * 4),
            depth: Vec::with_capacity(n),
            ids: Vec::with_capacity(n),
        };
        self.gpu.read_buffer(&readback, |data| {
            let rows = |k: usize| {
                data[k * target_bytes as usize..(k + 1) * target_bytes as usize]
                    .chunks_exact(row as usize)
                    .flat_map(|r| r[..w as usize * 4].chunks_exact(4))
            };
            for px in rows(0) {
                image.rgba.extend_from_slice(px);
            }
            image.ids.extend(rows(1).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])));
            image.depth.extend(rows(2).map(|b| f32::from_bits(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))));
        })?;
        Ok(image)
    }

    /// The full-detail scene of `db`: every object at LOD 0 under its transform, drawn in id
    /// order ([`Image::ids`] are object ids).
    pub fn render_full(&self, db: &Database, view: &View, mode: ColorMode) -> Result<Image> {
        let catalog = db.catalog();
        let parts: Vec<Part> = (0..catalog.objects.len() as u32)
            .map(|id| Part { kind: ItemKind::Object, id, lod: 0, dov: None, lod_ref: catalog.object_lods(id)[0] })
            .collect();
        self.render_parts(db, &parts, view, mode)
    }

    /// A query's answer: each item at its level, objects under their transforms, internal LODs
    /// in world space, drawn in (kind, id) order — objects by id first, then nodes — so that
    /// an answer of objects at LOD 0 draws exactly as [`Renderer::render_full`] does.
    /// [`Image::ids`] are indices into the answer's items.
    pub fn render_answer(&self, db: &Database, answer: &Answer, view: &View, mode: ColorMode) -> Result<Image> {
        self.render_items(db, &answer.items.iter().collect::<Vec<_>>(), view, mode)
    }

    /// What a walkthrough `session` draws from `view`, shaded: its current answer culled as
    /// [`Session::frame_items`] culls it from `view.eye` looking along `view.look`.
    /// [`Image::ids`] are indices into those items. Errors before the session's first step.
    pub fn render_session(&self, session: &Session, view: &View) -> Result<Image> {
        if session.answer().is_none() {
            return Err(Error::bad_param(Param::Fidelity, "the session has taken no step yet"));
        }
        let items = session.frame_items(view.eye, Some(view.look));
        self.render_items(session.database(), &items, view, ColorMode::Shaded)
    }

    /// `items` as [`Renderer::render_answer`] draws an answer's.
    fn render_items(&self, db: &Database, items: &[&Item], view: &View, mode: ColorMode) -> Result<Image> {
        let mut order: Vec<usize> = (0..items.len()).collect();
        order.sort_by_key(|&i| (items[i].kind, items[i].id));
        let parts: Vec<Part> = order
            .iter()
            .map(|&i| {
                let it = items[i];
                Part { kind: it.kind, id: it.id, lod: it.lod, dov: Some(it.dov), lod_ref: it.lod_ref }
            })
            .collect();
        let mut image = self.render_parts(db, &parts, view, mode)?;
        for id in image.ids.iter_mut().filter(|i| **i != NO_ITEM) {
            *id = order[*id as usize] as u32;
        }
        Ok(image)
    }

    fn render_parts(&self, db: &Database, parts: &[Part], view: &View, mode: ColorMode) -> Result<Image> {
        // Objects share base meshes: load each stored LOD once.
        let mut meshes: HashMap<u64, Mesh> = HashMap::new();
        for p in parts {
            if let std::collections::hash_map::Entry::Vacant(e) = meshes.entry(p.lod_ref.offset) {
                e.insert(db.lod_mesh(&p.lod_ref)?);
            }
        }
        let drawables: Vec<Drawable> = parts
            .iter()
            .map(|p| Drawable {
                mesh: &meshes[&p.lod_ref.offset],
                transform: db.transform_of(p.kind, p.id),
                color: item_color(mode, p.kind, p.lod, p.dov),
            })
            .collect();
        self.draw(&drawables, view)
    }
}

fn attachment(view: &wgpu::TextureView, clear: wgpu::Color) -> Option<wgpu::RenderPassColorAttachment<'_>> {
    Some(wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store },
    })
}

/// One item to load and draw.
struct Part {
    kind: ItemKind,
    id: u32,
    lod: u32,
    dov: Option<f32>,
    lod_ref: LodRef,
}

fn create_pipeline(device: &wgpu::Device, bind_layout: &wgpu::BindGroupLayout) -> wgpu::RenderPipeline {
    let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("render"),
        source: wgpu::ShaderSource::Wgsl(include_str!("render.wgsl").into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("render"),
        bind_group_layouts: &[Some(bind_layout)],
        immediate_size: 0,
    });
    let color_attributes = wgpu::vertex_attr_array![2 => Uint32];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("render"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[
                Some(Vertex::layout()),
                Some(wgpu::VertexBufferLayout {
                    array_stride: 4,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &color_attributes,
                }),
            ],
        },
        primitive: crate::gfx::two_sided_triangles(),
        depth_stencil: Some(crate::gfx::reverse_z_depth()),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[
                Some(wgpu::ColorTargetState { format: COLOR_FORMAT, blend: None, write_mask: wgpu::ColorWrites::ALL }),
                Some(wgpu::ColorTargetState { format: ID_FORMAT, blend: None, write_mask: wgpu::ColorWrites::ALL }),
                Some(wgpu::ColorTargetState {
                    format: DEPTH_OUT_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                }),
            ],
        }),
        multiview_mask: None,
        cache: None,
    })
}
