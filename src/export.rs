//! Answers and whole scenes out as glTF 2.0 binaries (`.glb`), which any viewer opens: one node per
//! item, its mesh at the chosen level; items drawing the same stored LOD record share one glTF
//! mesh (instances stay instances); `extras` on each node say what it is (kind, id, name, DoV,
//! LOD level, error).

use std::collections::HashMap;
use std::path::Path;

use glam::{Mat4, Vec3};
use serde_json::{Value, json};

use crate::db::Database;
use crate::error::{Error, Result};
use crate::format::catalog::LodRef;
use crate::query::{Answer, ItemKind};

/// One node to write: what it draws, under which transform, and what it is.
struct Part {
    kind: ItemKind,
    id: u32,
    name: String,
    lod: u32,
    dov: Option<f32>,
    lod_ref: LodRef,
    transform: Mat4,
}

/// The answer as a `.glb` at `out`: every item a node at its level. Refuses an existing `out`.
pub fn write_answer_glb(db: &Database, answer: &Answer, out: &Path) -> Result<()> {
    let parts = answer
        .items
        .iter()
        .map(|i| Part {
            kind: i.kind,
            id: i.id,
            name: i.name.to_string(),
            lod: i.lod,
            dov: Some(i.dov),
            lod_ref: i.lod_ref,
            transform: transform_of(db, i.kind, i.id),
        })
        .collect::<Vec<_>>();
    write_glb(db, &parts, out)
}

/// The whole scene as a `.glb` at `out`: every object at its level `lod` (its coarsest where its
/// chain is shorter; 0 = full detail). Refuses an existing `out`.
pub fn write_scene_glb(db: &Database, lod: u32, out: &Path) -> Result<()> {
    let catalog = db.catalog();
    let parts = (0..catalog.objects.len() as u32)
        .map(|o| {
            let chain = catalog.object_lods(o);
            let l = (lod as usize).min(chain.len() - 1);
            Part {
                kind: ItemKind::Object,
                id: o,
                name: catalog.objects[o as usize].name.to_string(),
                lod: l as u32,
                dov: None,
                lod_ref: chain[l],
                transform: transform_of(db, ItemKind::Object, o),
            }
        })
        .collect::<Vec<_>>();
    write_glb(db, &parts, out)
}

fn transform_of(db: &Database, kind: ItemKind, id: u32) -> Mat4 {
    match kind {
        ItemKind::Object => Mat4::from_cols_array(&db.catalog().objects[id as usize].transform),
        ItemKind::Node => Mat4::IDENTITY,
    }
}

fn write_glb(db: &Database, parts: &[Part], out: &Path) -> Result<()> {
    if out.exists() {
        return Err(Error::bad_file(out, "exists; choose another file"));
    }
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes) = (Vec::new(), Vec::new(), Vec::new());
    let mut mesh_of: HashMap<u64, usize> = HashMap::new();
    let mut nodes = Vec::new();
    for p in parts {
        let mesh = match mesh_of.get(&p.lod_ref.offset) {
            Some(&m) => m,
            None => {
                let m = db.lod_mesh(&p.lod_ref)?;
                let (lo, hi) = m
                    .positions
                    .iter()
                    .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &q| (lo.min(q.into()), hi.max(q.into())));
                let positions = push_view(&mut bin, &mut views, bytemuck::cast_slice(&m.positions), 34962);
                let indices = push_view(&mut bin, &mut views, bytemuck::cast_slice(&m.indices), 34963);
                accessors.push(json!({ "bufferView": positions, "componentType": 5126, "count": m.positions.len(),
                    "type": "VEC3", "min": lo.to_array(), "max": hi.to_array() }));
                accessors.push(json!({ "bufferView": indices, "componentType": 5125, "count": m.indices.len(), "type": "SCALAR" }));
                meshes.push(json!({ "primitives": [{ "attributes": { "POSITION": accessors.len() - 2 },
                    "indices": accessors.len() - 1 }] }));
                mesh_of.insert(p.lod_ref.offset, meshes.len() - 1);
                meshes.len() - 1
            }
        };
        let kind = match p.kind {
            ItemKind::Object => "object",
            ItemKind::Node => "node",
        };
        let mut extras = json!({ "kind": kind, "id": p.id, "name": p.name, "lod": p.lod, "error": p.lod_ref.error });
        if let Some(d) = p.dov {
            extras["dov"] = json!(d);
        }
        let mut node = json!({ "name": p.name, "mesh": mesh, "extras": extras });
        if p.transform != Mat4::IDENTITY {
            node["matrix"] = json!(p.transform.to_cols_array());
        }
        nodes.push(node);
    }
    let node_ids: Vec<usize> = (0..nodes.len()).collect();
    let mut doc = json!({
        "asset": { "version": "2.0", "generator": concat!("hdov ", env!("CARGO_PKG_VERSION")) },
        "scene": 0,
        "scenes": [{ "nodes": node_ids }],
        "nodes": nodes,
        "meshes": meshes,
        "accessors": accessors,
        "bufferViews": views,
    });
    if !bin.is_empty() {
        doc["buffers"] = json!([{ "byteLength": bin.len() }]);
    }
    write_new(out, &glb(&doc, &bin))
}

/// Writes `bytes` to a new file `out` (never over an existing one), synced; removes what it
/// created if the write fails.
fn write_new(out: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new().write(true).create_new(true).open(out).map_err(|e| Error::io(out, e))?;
    if let Err(e) = f.write_all(bytes).and_then(|()| f.sync_all()) {
        drop(f);
        let _ = std::fs::remove_file(out);
        return Err(Error::io(out, e));
    }
    Ok(())
}

/// Appends `data` to `bin` (4-byte aligned) as a new buffer view for `target`; its index.
fn push_view(bin: &mut Vec<u8>, views: &mut Vec<Value>, data: &[u8], target: u32) -> usize {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    views.push(json!({ "buffer": 0, "byteOffset": bin.len(), "byteLength": data.len(), "target": target }));
    bin.extend_from_slice(data);
    views.len() - 1
}

/// The `.glb` container: header, JSON chunk (space-padded), BIN chunk (zero-padded).
fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).expect("serialisable");
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&json);
    if !bin.is_empty() {
        out.extend((bin.len() as u32).to_le_bytes());
        out.extend(b"BIN\0");
        out.extend(&bin);
    }
    out
}
