//! The one wgpu set-up, shared by the DoV GPU backend ([`crate::dov::gpu`]) and the offscreen
//! renderer ([`crate::render`]): adapter and device requests, the vertex format both draw
//! (world position relative to an origin + a 32-bit id), mesh upload, and blocking buffer
//! read-back.
//!
//! **GL caveat**: copying layers of a 2D-array texture to a buffer reads back zeros on wgpu's GL
//! backend, so every render target that is read back is its own 2D texture.

use std::sync::mpsc;

use glam::{Mat4, Vec3};
use wgpu::util::DeviceExt;

use crate::error::{Error, Result};
use crate::scene::Mesh;

/// One vertex: a position relative to the drawing's origin, and the id of what it belongs to.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub id: u32,
}

impl Vertex {
    /// Shader locations 0 (`vec3<f32>` position) and 1 (`u32` id).
    pub const ATTRIBUTES: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32];

    /// The vertex buffer layout of [`Vertex::ATTRIBUTES`].
    pub fn layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &Self::ATTRIBUTES,
        }
    }
}

/// Appends `mesh` transformed by `m` as unshared triangles (winding reversed when `m` mirrors, so
/// that front faces stay front faces), relative to `origin`, with id `id`.
pub fn push_world(vertices: &mut Vec<Vertex>, mesh: &Mesh, m: &Mat4, origin: Vec3, id: u32) {
    let mirrored = m.determinant() < 0.0;
    for t in mesh.triangles() {
        let t = if mirrored { [t[0], t[2], t[1]] } else { t };
        for p in t {
            let rel = m.transform_point3(p) - origin;
            vertices.push(Vertex { position: rel.to_array(), id });
        }
    }
}

/// The name of the adapter wgpu would use (e.g. "llvmpipe (LLVM 19.1.7, 256 bits) on Gl"), or
/// `None` when wgpu finds none. Costs an instance and an adapter request.
pub fn adapter_available() -> Option<String> {
    request_adapter().ok().map(|a| describe(&a.get_info()))
}

/// Whether the adapter is real graphics hardware rather than a CPU rasteriser (llvmpipe,
/// lavapipe, WARP).
pub fn hardware_adapter_available() -> bool {
    request_adapter().is_ok_and(|a| a.get_info().device_type != wgpu::DeviceType::Cpu)
}

/// The adapter. `WGPU_BACKEND` (e.g. `gl`, `vulkan`) picks the backend; otherwise the native
/// APIs (Vulkan, Metal, DX12) are asked first and GL only when they offer nothing, which also
/// keeps EGL from probing (and complaining about) display servers needlessly.
fn request_adapter() -> std::result::Result<wgpu::Adapter, wgpu::RequestAdapterError> {
    let request = |backends: Option<wgpu::Backends>| {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle().with_env();
        if let Some(b) = backends {
            desc.backends = b;
        }
        pollster::block_on(wgpu::Instance::new(desc).request_adapter(&adapter_options()))
    };
    quiet_wayland_log();
    if std::env::var_os("WGPU_BACKEND").is_some() {
        return request(None);
    }
    request(Some(wgpu::Backends::PRIMARY)).or_else(|_| request(Some(wgpu::Backends::GL)))
}

/// Silences libwayland-client's log in this process. Mesa's drivers probe for a Wayland
/// display while wgpu asks them for adapters, and without `XDG_RUNTIME_DIR` (servers, CI,
/// containers) libwayland prints `error: XDG_RUNTIME_DIR is invalid or not set in the
/// environment.` on stderr, which reads as hdov failing. hdov draws offscreen and opens no
/// window, so nothing it does needs that log. Loading the library (when present) and setting
/// its client log handler once, before the first instance, keeps the probe quiet; the
/// drivers' own failures still come back through wgpu (decision 72).
fn quiet_wayland_log() {
    #[cfg(target_os = "linux")]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        /// `wl_log_func_t`: `void (*)(const char *format, va_list args)`; the arguments are ignored.
        unsafe extern "C" fn ignore(_format: *const std::ffi::c_char, _args: *mut std::ffi::c_void) {}
        type SetHandler = unsafe extern "C" fn(unsafe extern "C" fn(*const std::ffi::c_char, *mut std::ffi::c_void));
        ONCE.call_once(|| {
            // SAFETY: loading libwayland-client runs no initialiser with preconditions, and
            // `wl_log_set_handler_client` only stores the pointer to a function that lives for
            // the whole process. The library is kept loaded (leaked) so that the handler stays
            // set for the drivers, which share the same loaded copy.
            unsafe {
                let Ok(library) = libloading::Library::new("libwayland-client.so.0") else { return };
                if let Ok(set) = library.get::<SetHandler>(b"wl_log_set_handler_client\0") {
                    set(ignore);
                }
                std::mem::forget(library);
            }
        });
    }
}

fn adapter_options() -> wgpu::RequestAdapterOptions<'static, 'static> {
    wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        apply_limit_buckets: false,
    }
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({}) on {:?}", info.name, info.driver_info, info.backend)
}

/// An adapter's device and queue, with the adapter's full limits.
pub struct Gpu {
    /// The adapter's name, driver and backend, e.g. "llvmpipe (...) on Vulkan".
    pub adapter_name: String,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub limits: wgpu::Limits,
    /// Whether `multi_draw_indexed_indirect` runs natively with per-draw first instances: the
    /// device has [`wgpu::Features::INDIRECT_FIRST_INSTANCE`] (requested when the adapter offers
    /// it) and [`wgpu::DownlevelFlags::INDIRECT_EXECUTION`].
    pub indirect_draws: bool,
}

impl Gpu {
    /// Requests the adapter and a device with all its limits. Fails with [`Error::Gpu`]
    /// ("no adapter: ..." or "ADAPTER: no device: ...").
    pub fn open(label: &str) -> Result<Gpu> {
        let adapter = request_adapter().map_err(|e| Error::Gpu(format!("no adapter: {e}")))?;
        let adapter_name = describe(&adapter.get_info());
        let limits = adapter.limits();
        let features = adapter.features() & wgpu::Features::INDIRECT_FIRST_INSTANCE;
        let indirect_draws = !features.is_empty()
            && adapter.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::INDIRECT_EXECUTION);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some(label),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| Error::Gpu(format!("{adapter_name}: no device: {e}")))?;
        Ok(Gpu { adapter_name, device, queue, limits, indirect_draws })
    }

    /// Checks that a `width × height` texture fits the device.
    pub fn check_texture_size(&self, what: &str, width: u32, height: u32) -> Result<()> {
        let max = self.limits.max_texture_dimension_2d;
        if width > max || height > max {
            return Err(Error::Gpu(format!("{what} {width}×{height} exceeds the adapter's texture limit {max}")));
        }
        Ok(())
    }

    /// Uploads `vertices` into a vertex buffer; `None` when there are none. Fails when they
    /// exceed the device's buffer limit.
    pub fn upload_vertices(&self, label: &str, vertices: &[Vertex]) -> Result<Option<wgpu::Buffer>> {
        if vertices.len() > u32::MAX as usize {
            return Err(Error::Gpu(format!("{} vertices exceed u32 vertex indices", vertices.len())));
        }
        self.upload(label, bytemuck::cast_slice(vertices), wgpu::BufferUsages::VERTEX)
    }

    /// Uploads `contents` into a new buffer of `usage` (`label` names it in errors too); `None`
    /// when there are no bytes. Fails when they exceed the device's buffer limit.
    pub fn upload(&self, label: &str, contents: &[u8], usage: wgpu::BufferUsages) -> Result<Option<wgpu::Buffer>> {
        let bytes = contents.len() as u64;
        if bytes > self.limits.max_buffer_size {
            return Err(Error::Gpu(format!(
                "{}: {bytes} bytes of {label} exceed the buffer limit {}",
                self.adapter_name, self.limits.max_buffer_size
            )));
        }
        Ok((!contents.is_empty()).then(|| {
            self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        }))
    }

    /// A 2D render target of `format` that can be copied out.
    pub fn target(&self, label: &str, width: u32, height: u32, format: wgpu::TextureFormat) -> wgpu::Texture {
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        self.texture_2d(label, width, height, format, usage)
    }

    /// A reverse-Z depth buffer (`Depth32Float`, see [`reverse_z_depth`]) of `width × height`.
    pub fn depth_buffer(&self, label: &str, width: u32, height: u32) -> wgpu::Texture {
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
        self.texture_2d(label, width, height, wgpu::TextureFormat::Depth32Float, usage)
    }

    /// One single-sampled 2D texture without mip levels.
    fn texture_2d(
        &self,
        label: &str,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> wgpu::Texture {
        self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    }

    /// A buffer to copy textures into and map for reading.
    pub fn readback_buffer(&self, label: &str, size: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Maps `buffer` (blocking until the GPU is done), hands its bytes to `read`, unmaps it.
    pub fn read_buffer(&self, buffer: &wgpu::Buffer, read: impl FnOnce(&[u8])) -> Result<()> {
        let slice = buffer.slice(..);
        let (sender, receiver) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |result| {
            // The receiver outlives the poll below; a failed send only means it gave up.
            let _ = sender.send(result);
        });
        let name = &self.adapter_name;
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| Error::Gpu(format!("{name}: poll: {e}")))?;
        receiver
            .recv()
            .map_err(|e| Error::Gpu(format!("{name}: map callback lost: {e}")))?
            .map_err(|e| Error::Gpu(format!("{name}: map: {e}")))?;
        {
            let data = slice.get_mapped_range().map_err(|e| Error::Gpu(format!("{name}: mapped range: {e}")))?;
            read(&data);
        }
        buffer.unmap();
        Ok(())
    }
}

/// A bind group layout of one uniform buffer of `T` at binding 0, seen by `visibility`.
pub fn uniform_layout<T>(device: &wgpu::Device, label: &str, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<T>() as u64),
            },
            count: None,
        }],
    })
}

/// Triangle lists drawn from both sides (counter-clockwise is the front): a back face is a
/// visible surface too, and open or inverted meshes still cover their pixels.
pub fn two_sided_triangles() -> wgpu::PrimitiveState {
    wgpu::PrimitiveState {
        topology: wgpu::PrimitiveTopology::TriangleList,
        front_face: wgpu::FrontFace::Ccw,
        cull_mode: None,
        ..Default::default()
    }
}

/// Reverse-Z depth testing into a `Depth32Float` buffer: larger is nearer, and at an exact tie
/// the later draw wins (so draw order decides coplanar faces the same way every time).
pub fn reverse_z_depth() -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: wgpu::TextureFormat::Depth32Float,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::GreaterEqual),
        stencil: wgpu::StencilState::default(),
        bias: wgpu::DepthBiasState::default(),
    }
}

/// Bytes per row of a `width`-texel copy of `texel_bytes`-byte texels, padded to wgpu's copy
/// alignment.
pub fn padded_row_bytes(width: u32, texel_bytes: u32) -> u32 {
    (width * texel_bytes).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
}
