//! glTF 2.0 import (`.gltf` with its buffers, or `.glb`): the node hierarchy flattened with its
//! transforms, every node with a mesh one object, a mesh used by several nodes one base mesh with
//! instances, and `EXT_mesh_gpu_instancing` one instance per transform.
//!
//! The `gltf` crate parses the JSON (without its validation, which refuses required extensions
//! it does not know); everything read from buffers is checked here first: accessors against
//! their views and buffers (before anything is allocated, so a claim of 2^31 elements costs
//! nothing), component types, index ranges, finite coordinates, node cycles. Triangles, strips
//! and fans are imported; points and lines are skipped and counted in the warnings; materials are
//! not needed. Compressed geometry (`KHR_draco_mesh_compression`, `EXT_meshopt_compression`) and
//! quantized attributes (`KHR_mesh_quantization`) are refused, naming the extension.

use std::path::Path;

use glam::{Mat4, Quat, Vec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use super::{BaseMesh, Mesh, Object, Scene};
use crate::error::{Error, Result};

/// Required extensions that change how geometry is stored, which this reader does not decode.
const REFUSED: [&str; 3] = ["KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_mesh_quantization"];

/// Required extensions this reader handles, or that do not touch geometry.
fn understood(ext: &str) -> bool {
    ext == "EXT_mesh_gpu_instancing"
        || ["KHR_materials_", "KHR_texture_", "EXT_texture_", "KHR_lights_"].iter().any(|p| ext.starts_with(p))
}

/// Reads a glTF file (see the module documentation); the warnings name what was skipped.
pub fn read(path: &Path) -> Result<(Scene, Vec<String>)> {
    let bad = |reason: String| Error::bad_file(path, reason);
    let bytes = super::files::read_whole(path)?;
    // The gltf crate (1.4) subtracts the 12-byte header from a GLB's declared length unchecked
    // (a panic where overflow is checked, found by the `scene_gltf` fuzz target): refuse a
    // length shorter than the header itself first.
    if let Some(declared) = bytes.strip_prefix(b"glTF").and_then(|b| b.get(4..8)) {
        let declared = u32::from_le_bytes(declared.try_into().expect("four bytes"));
        if declared < 12 {
            return Err(bad(format!("not a glTF file: the GLB header declares {declared} bytes, fewer than the header's 12")));
        }
    }
    let gltf = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| bad(format!("not a glTF file: {e}")))?;
    let doc = &gltf.document;
    for ext in doc.extensions_required() {
        if REFUSED.contains(&ext) {
            return Err(bad(format!("uses {ext}, which hdov does not decode; export without it")));
        }
        if !understood(ext) {
            return Err(bad(format!("requires the extension {ext}, which hdov does not know")));
        }
    }
    // The crate's validation (indices in range, the schema's rules), less its refusal of the
    // required extensions it does not know, which the lines above judged.
    {
        use gltf::json::validation::Validate;
        let root = doc.as_json();
        // gltf-json 1.4's mesh check reads a primitive's POSITION accessor without a bounds
        // check (it panicked on an index past the accessors, found by the `scene_gltf` fuzz
        // target): every attribute's index is checked here first.
        let accessors = root.accessors.len();
        for (m, mesh) in root.meshes.iter().enumerate() {
            for (k, prim) in mesh.primitives.iter().enumerate() {
                if let Some(i) = prim.attributes.values().map(|a| a.value()).find(|&i| i >= accessors) {
                    return Err(bad(format!(
                        "invalid glTF: mesh {m} primitive {k}: accessor {i} of {accessors} is past the accessors"
                    )));
                }
            }
        }
        let mut first: Option<String> = None;
        root.validate(root, gltf::json::Path::new, &mut |at, e| {
            let at = at();
            if first.is_none() && !at.as_str().starts_with("extensionsRequired") {
                first = Some(format!("{}: {e}", at.as_str()));
            }
        });
        if let Some(reason) = first {
            return Err(bad(format!("invalid glTF: {reason}")));
        }
    }
    let buffers = load_buffers(doc, gltf.blob.as_deref(), path)?;
    let mut copies = CopyBudget::of(&buffers);
    let mut warnings = Vec::new();
    // Base meshes by glTF mesh index (`None`: no triangles).
    let mut meshes: Vec<Option<u32>> = Vec::new();
    let mut scene = Scene::default();
    let mut degenerate = 0;
    for mesh in doc.meshes() {
        let name = mesh.name().map_or_else(|| format!("mesh {}", mesh.index()), str::to_string);
        let mut out = Mesh::default();
        for prim in mesh.primitives() {
            let mode = prim.mode();
            if matches!(mode, Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip) {
                warnings.push(format!("{}: mesh '{name}': a {mode:?} primitive skipped (not triangles)", path.display()));
                continue;
            }
            let positions = prim
                .get(&gltf::Semantic::Positions)
                .ok_or_else(|| bad(format!("mesh '{name}': a primitive without positions")))?;
            let positions = read_floats::<3>(&positions, &buffers).map_err(|r| bad(format!("mesh '{name}': positions: {r}")))?;
            let indices: Vec<u32> = match prim.indices() {
                Some(a) => read_indices(&a, &buffers).map_err(|r| bad(format!("mesh '{name}': indices: {r}")))?,
                None => (0..positions.len() as u32).collect(),
            };
            if let Some(&i) = indices.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(bad(format!("mesh '{name}': index {i} past its {} vertices", positions.len())));
            }
            let triangles = triangles(mode, &indices);
            copies
                .charge(12 * positions.len() as u64 + 4 * triangles.len() as u64)
                .map_err(|r| bad(format!("mesh '{name}': {r}")))?;
            // Indices are u32: the mesh's vertices must stay within them.
            let base = out.positions.len() as u32;
            if u32::try_from(out.positions.len() + positions.len()).is_err() {
                return Err(bad(format!("mesh '{name}': more than {} vertices", u32::MAX)));
            }
            out.positions.extend(positions);
            out.indices.extend(triangles.into_iter().map(|i| i + base));
        }
        degenerate += out.drop_degenerate();
        if out.indices.is_empty() {
            meshes.push(None);
            continue;
        }
        out.check().map_err(|r| bad(format!("mesh '{name}': {r}")))?;
        meshes.push(Some(scene.meshes.len() as u32));
        scene.meshes.push(BaseMesh { name, mesh: out });
    }
    if degenerate > 0 {
        warnings.push(format!("{}: {degenerate} zero-area triangles dropped (never seen)", path.display()));
    }
    // The scene graph, flattened from its roots.
    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => {
            let children: Vec<usize> = doc.nodes().flat_map(|n| n.children().map(|c| c.index())).collect();
            doc.nodes().filter(|n| !children.contains(&n.index())).collect()
        }
    };
    let mut seen = vec![false; doc.nodes().count()];
    let mut stack: Vec<(gltf::Node, Mat4)> = roots.into_iter().rev().map(|n| (n, Mat4::IDENTITY)).collect();
    let node_name = |node: &gltf::Node| node.name().map_or_else(|| format!("node {}", node.index()), str::to_string);
    let file_names: Vec<String> = doc.nodes().map(|n| node_name(&n)).collect();
    let mut names = super::UniqueNames::new(file_names.iter().map(String::as_str));
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut seen[node.index()], true) {
            return Err(bad(format!("node {} is reached twice: a cycle or a node with two parents", node.index())));
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let world = parent * local;
        if !world.is_finite() {
            return Err(bad(format!("node {} has a non-finite transform", node.index())));
        }
        if let Some(mesh) = node.mesh() {
            match meshes[mesh.index()] {
                None => warnings.push(format!("{}: node {}: its mesh has no triangles; skipped", path.display(), node.index())),
                Some(m) => {
                    let base = node_name(&node);
                    let transforms =
                        instances(doc, &node, &buffers).map_err(|r| bad(format!("node {}: {r}", node.index())))?;
                    // GPU instances come from buffer data that many nodes may share.
                    if transforms.len() > 1 {
                        copies
                            .charge(64 * transforms.len() as u64)
                            .map_err(|r| bad(format!("node {}: {r}", node.index())))?;
                    }
                    for transform in transforms {
                        let name = names.give(&base);
                        scene.objects.push(Object { name, mesh: m, transform: world * transform, part: None });
                    }
                }
            }
        }
        for child in node.children().collect::<Vec<_>>().into_iter().rev() {
            stack.push((child, world));
        }
    }
    if scene.objects.is_empty() {
        return Err(bad("no triangles: the glTF file's scene holds no triangle mesh".into()));
    }
    // Base meshes no node uses are not stored.
    let mut used = vec![false; scene.meshes.len()];
    scene.objects.iter().for_each(|o| used[o.mesh as usize] = true);
    if used.iter().any(|u| !u) {
        let mut remap = vec![u32::MAX; used.len()];
        let mut kept = Vec::new();
        for (i, m) in std::mem::take(&mut scene.meshes).into_iter().enumerate() {
            if used[i] {
                remap[i] = kept.len() as u32;
                kept.push(m);
            }
        }
        scene.meshes = kept;
        scene.objects.iter_mut().for_each(|o| o.mesh = remap[o.mesh as usize]);
    }
    Ok((scene, warnings))
}

/// How many times over the buffers' bytes the meshes may copy (primitives sharing accessors).
const READ_OVER: u64 = 16;

/// What a file's meshes and instances copy out of its buffers: accessors may be shared by
/// primitives and instance transforms by nodes, each copied again, so the copies may come to
/// [`READ_OVER`] times the buffers (and 1 MiB), not a file's worth per line of JSON.
struct CopyBudget {
    copied: u64,
    buffers: u64,
}

impl CopyBudget {
    fn of(buffers: &[Vec<u8>]) -> CopyBudget {
        CopyBudget { copied: 0, buffers: buffers.iter().map(|b| b.len() as u64).sum() }
    }

    /// Counts `bytes` more; the reason when the copies pass the budget.
    fn charge(&mut self, bytes: u64) -> std::result::Result<(), String> {
        self.copied = self.copied.saturating_add(bytes);
        let limit = READ_OVER.saturating_mul(self.buffers).saturating_add(1 << 20);
        if self.copied > limit {
            return Err(format!(
                "its meshes and instances copy {} bytes from {} bytes of buffers; at most {READ_OVER} times over are read",
                self.copied, self.buffers
            ));
        }
        Ok(())
    }
}

/// Every buffer's bytes: the `.glb`'s binary chunk (buffer 0 only, as the GLB format has it), a
/// `data:` URI, or a file beside `path`. The declared lengths are summed and bounded before any
/// byte is read.
fn load_buffers(doc: &gltf::Document, blob: Option<&[u8]>, path: &Path) -> Result<Vec<Vec<u8>>> {
    let bad = |reason: String| Error::bad_file(path, reason);
    let declared = doc.buffers().try_fold(0u64, |sum, b| sum.checked_add(b.length() as u64));
    if declared.is_none_or(|d| d > super::files::MAX_FILE_BYTES) {
        return Err(bad(format!("its buffers declare more than {} bytes in all", super::files::MAX_FILE_BYTES)));
    }
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let data = match buffer.source() {
            gltf::buffer::Source::Bin if buffer.index() != 0 => {
                return Err(bad(format!("buffer {} has no URI; only buffer 0 is the binary chunk", buffer.index())));
            }
            gltf::buffer::Source::Bin => {
                blob.ok_or_else(|| bad(format!("buffer {} refers to a binary chunk the file lacks", buffer.index())))?.to_vec()
            }
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                use base64::Engine;
                let (_, encoded) = uri
                    .split_once(";base64,")
                    .ok_or_else(|| bad(format!("buffer {}: a data URI that is not base64", buffer.index())))?;
                base64::engine::general_purpose::STANDARD
                    .decode(encoded)
                    .map_err(|e| bad(format!("buffer {}: bad base64: {e}", buffer.index())))?
            }
            gltf::buffer::Source::Uri(uri) => {
                // Inside the scene's folder, and no more than its declared length (up to 3 bytes
                // of 4-byte alignment padding may follow it, as in a GLB's binary chunk).
                let file = super::files::beside(path, uri)?;
                super::files::read_declared(&file, buffer.length() as u64, 3)?
            }
        };
        if data.len() < buffer.length() {
            return Err(bad(format!(
                "buffer {} holds {} bytes, the file says {}",
                buffer.index(),
                data.len(),
                buffer.length()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

/// The bytes of accessor `a`'s elements (`size` bytes each) and their stride, checked to lie
/// inside its view and buffer before anything is read or allocated.
fn elements<'b>(a: &gltf::Accessor, buffers: &'b [Vec<u8>], size: usize) -> std::result::Result<(&'b [u8], usize), String> {
    if a.sparse().is_some() {
        return Err("sparse accessors are not supported".into());
    }
    let view = a.view().ok_or("an accessor without a buffer view")?;
    let buffer = &buffers[view.buffer().index()];
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!("a stride of {stride} bytes for {size}-byte elements"));
    }
    let (count, start) = (a.count(), view.offset().checked_add(a.offset()).ok_or("an offset that overflows")?);
    let view_end = view.offset().checked_add(view.length()).ok_or("a view that overflows")?;
    if view_end > buffer.len() {
        return Err(format!("its view ends at byte {view_end}, past its buffer's {}", buffer.len()));
    }
    let need = match count {
        0 => 0,
        n => (n - 1).checked_mul(stride).and_then(|b| b.checked_add(size)).ok_or("an element count that overflows")?,
    };
    if start.checked_add(need).is_none_or(|end| end > view_end) {
        return Err(format!("{count} elements of {size} bytes do not fit its view of {} bytes", view.length()));
    }
    Ok((&buffer[start..start + need], stride))
}

/// A float accessor of `N` components (VEC3 or VEC4), element by element.
fn read_floats<const N: usize>(a: &gltf::Accessor, buffers: &[Vec<u8>]) -> std::result::Result<Vec<[f32; N]>, String> {
    let dimensions = match N {
        3 => Dimensions::Vec3,
        4 => Dimensions::Vec4,
        _ => unreachable!("VEC3 and VEC4 are read"),
    };
    if a.data_type() != DataType::F32 || a.dimensions() != dimensions || a.normalized() {
        return Err(format!("{:?} {:?}, expected float {dimensions:?}", a.data_type(), a.dimensions()));
    }
    let (bytes, stride) = elements(a, buffers, 4 * N)?;
    let f = |b: &[u8], k: usize| f32::from_le_bytes([b[4 * k], b[4 * k + 1], b[4 * k + 2], b[4 * k + 3]]);
    Ok((0..a.count()).map(|i| &bytes[i * stride..]).map(|b| std::array::from_fn(|k| f(b, k))).collect())
}

fn read_indices(a: &gltf::Accessor, buffers: &[Vec<u8>]) -> std::result::Result<Vec<u32>, String> {
    if a.dimensions() != Dimensions::Scalar {
        return Err(format!("{:?} indices", a.dimensions()));
    }
    let size = match a.data_type() {
        DataType::U8 => 1,
        DataType::U16 => 2,
        DataType::U32 => 4,
        t => return Err(format!("{t:?} indices")),
    };
    let (bytes, stride) = elements(a, buffers, size)?;
    Ok((0..a.count())
        .map(|i| {
            let b = &bytes[i * stride..];
            match size {
                1 => u32::from(b[0]),
                2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            }
        })
        .collect())
}

/// The triangles of a primitive's index list, strips and fans unrolled (each strip triangle
/// wound as the first).
fn triangles(mode: Mode, indices: &[u32]) -> Vec<u32> {
    match mode {
        Mode::TriangleStrip => (2..indices.len())
            .flat_map(|i| match i % 2 {
                0 => [indices[i - 2], indices[i - 1], indices[i]],
                _ => [indices[i - 1], indices[i - 2], indices[i]],
            })
            .collect(),
        Mode::TriangleFan => (2..indices.len()).flat_map(|i| [indices[0], indices[i - 1], indices[i]]).collect(),
        _ => indices[..indices.len() / 3 * 3].to_vec(),
    }
}

/// The node's instance transforms: one identity, or `EXT_mesh_gpu_instancing`'s
/// translation · rotation · scale per instance.
fn instances(doc: &gltf::Document, node: &gltf::Node, buffers: &[Vec<u8>]) -> std::result::Result<Vec<Mat4>, String> {
    let Some(ext) = node.extension_value("EXT_mesh_gpu_instancing") else { return Ok(vec![Mat4::IDENTITY]) };
    let attributes = ext.get("attributes").and_then(|a| a.as_object()).ok_or("EXT_mesh_gpu_instancing without attributes")?;
    let doc_accessor = |name: &str| -> std::result::Result<Option<gltf::Accessor>, String> {
        match attributes.get(name) {
            None => Ok(None),
            Some(v) => {
                let i = v.as_u64().ok_or(format!("instancing {name} is not an accessor index"))? as usize;
                doc.accessors().nth(i).map(Some).ok_or(format!("instancing {name}: no accessor {i}"))
            }
        }
    };
    let t = doc_accessor("TRANSLATION")?.map(|a| read_floats::<3>(&a, buffers)).transpose()?;
    let r = doc_accessor("ROTATION")?.map(|a| read_floats::<4>(&a, buffers)).transpose()?;
    let s = doc_accessor("SCALE")?.map(|a| read_floats::<3>(&a, buffers)).transpose()?;
    let counts: Vec<usize> = [t.as_ref().map(Vec::len), r.as_ref().map(Vec::len), s.as_ref().map(Vec::len)].into_iter().flatten().collect();
    let n = *counts.first().ok_or("EXT_mesh_gpu_instancing names no attribute")?;
    if counts.iter().any(|&c| c != n) {
        return Err(format!("instancing attributes of different counts {counts:?}"));
    }
    Ok((0..n)
        .map(|i| {
            let translation = t.as_ref().map_or(Vec3::ZERO, |t| Vec3::from(t[i]));
            let rotation = r.as_ref().map_or(Quat::IDENTITY, |r| Quat::from_array(r[i]).normalize());
            let scale = s.as_ref().map_or(Vec3::ONE, |s| Vec3::from(s[i]));
            Mat4::from_scale_rotation_translation(scale, rotation, translation)
        })
        .collect())
}
