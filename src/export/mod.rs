//! Answers and whole scenes out as glTF 2.0 binaries (`.glb`), which any viewer opens: one node per
//! item, its mesh at the chosen level; items drawing the same stored LOD record share one glTF
//! mesh (instances stay instances); `extras` on each node say what it is (kind, id, name, DoV,
//! LOD level, error).

mod slices;
pub mod tiles;

use std::collections::HashMap;
use std::path::Path;

use glam::{Mat4, Vec3};
use serde_json::{Value, json};

use crate::db::Database;
use crate::error::{Error, Result};
use crate::format::catalog::LodRef;
use crate::query::{Answer, Item, ItemKind};
use crate::scene::Mesh;

/// One node to write: the item it draws, and its DoV where it has one (an answer's).
struct Part<'a> {
    item: &'a Item,
    dov: Option<f32>,
}

/// The answer as a `.glb` at `out`: every item a node at its level. Refuses an existing `out`.
pub fn write_answer_glb(db: &Database, answer: &Answer, out: &Path) -> Result<()> {
    let parts: Vec<Part> = answer.items.iter().map(|i| Part { item: i, dov: Some(i.dov) }).collect();
    write_new(out, &glb_of(db, &parts)?)
}

/// The whole scene as a `.glb` at `out`: every object at its level `lod` (its coarsest where its
/// chain is shorter; 0 = full detail). Refuses an existing `out`.
pub fn write_scene_glb(db: &Database, lod: u32, out: &Path) -> Result<()> {
    let items = scene_items(db, lod)?;
    let parts: Vec<Part> = items.iter().map(|i| Part { item: i, dov: None }).collect();
    write_new(out, &glb_of(db, &parts)?)
}

/// Every object of the scene as an item at level `lod` (its coarsest where its chain is shorter),
/// in object order, with its box from the tree's leaves and DoV 0: the "full scene" that a viewer
/// compares an answer with. Reads every leaf page once.
pub fn scene_items(db: &Database, lod: u32) -> Result<Vec<Item>> {
    let catalog = db.catalog();
    let mut mbrs = vec![None; catalog.objects.len()];
    for n in 0..db.node_count() {
        let page = db.node(n)?;
        if page.node.is_leaf() {
            for e in &page.node.entries {
                if let Some(slot) = mbrs.get_mut(e.child as usize) {
                    *slot = Some(e.mbr);
                }
            }
        }
    }
    (0..catalog.objects.len() as u32)
        .map(|o| {
            let chain = catalog.object_lods(o);
            let l = (lod as usize).min(chain.len() - 1);
            let mbr = mbrs[o as usize]
                .ok_or_else(|| Error::bad_file(db.tree_file().path(), format!("no leaf holds object {o}")))?;
            Ok(Item {
                kind: ItemKind::Object,
                id: o,
                name: catalog.objects[o as usize].name.clone(),
                part: catalog.objects[o as usize].part,
                lod: l as u32,
                faces: chain[l].faces,
                dov: 0.0,
                mbr,
                lod_ref: chain[l],
            })
        })
        .collect()
}

/// One stored LOD level as a `.glb` of one node and one mesh, in the level's own coordinates
/// (mesh space for an object's level, world space for a node's): what a streaming client fetches
/// once per record and draws under each item's transform.
pub fn lod_glb(db: &Database, lod: &LodRef) -> Result<Vec<u8>> {
    Ok(mesh_glb(&db.lod_mesh(lod)?))
}

/// A mesh as a `.glb` of one node and one mesh.
pub fn mesh_glb(m: &Mesh) -> Vec<u8> {
    let mut bin = Vec::new();
    let (mut views, mut accessors) = (Vec::new(), Vec::new());
    let mesh = push_mesh(m, &mut bin, &mut views, &mut accessors);
    let doc = json!({
        "asset": asset(),
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [mesh],
        "materials": [plain_material()],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{ "byteLength": bin.len() }],
    });
    glb(&doc, &bin)
}

/// A light grey, rough, non-metallic surface: glTF's default material is fully metallic, which
/// clients without an environment map draw black (3D Tiles clients among them).
fn plain_material() -> Value {
    json!({ "name": "hdov", "pbrMetallicRoughness": { "baseColorFactor": [0.85, 0.83, 0.8, 1.0],
        "metallicFactor": 0.0, "roughnessFactor": 1.0 } })
}

fn asset() -> Value {
    json!({ "version": "2.0", "generator": concat!("hdov ", env!("CARGO_PKG_VERSION")) })
}

/// Appends one LOD's positions and indices to `bin`, with their views and accessors; returns the
/// glTF mesh (one primitive) that draws them.
fn push_mesh(m: &Mesh, bin: &mut Vec<u8>, views: &mut Vec<Value>, accessors: &mut Vec<Value>) -> Value {
    let (lo, hi) = m
        .positions
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &q| (lo.min(q.into()), hi.max(q.into())));
    let positions = push_view(bin, views, bytemuck::cast_slice(&m.positions), 34962);
    let indices = push_view(bin, views, bytemuck::cast_slice(&m.indices), 34963);
    accessors.push(json!({ "bufferView": positions, "componentType": 5126, "count": m.positions.len(),
        "type": "VEC3", "min": lo.to_array(), "max": hi.to_array() }));
    accessors.push(json!({ "bufferView": indices, "componentType": 5125, "count": m.indices.len(), "type": "SCALAR" }));
    json!({ "primitives": [{ "attributes": { "POSITION": accessors.len() - 2 }, "indices": accessors.len() - 1, "material": 0 }] })
}

/// The `.glb` of `parts`: items drawing the same stored record share one glTF mesh.
fn glb_of(db: &Database, parts: &[Part]) -> Result<Vec<u8>> {
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes) = (Vec::new(), Vec::new(), Vec::new());
    let mut mesh_of: HashMap<u64, usize> = HashMap::new();
    let mut nodes = Vec::new();
    for p in parts {
        let i = p.item;
        let mesh = match mesh_of.get(&i.lod_ref.offset) {
            Some(&m) => m,
            None => {
                meshes.push(push_mesh(&db.lod_mesh(&i.lod_ref)?, &mut bin, &mut views, &mut accessors));
                mesh_of.insert(i.lod_ref.offset, meshes.len() - 1);
                meshes.len() - 1
            }
        };
        let mut extras = json!({ "kind": i.kind, "id": i.id, "name": &*i.name, "lod": i.lod, "error": i.lod_ref.error });
        if let Some(d) = p.dov {
            extras["dov"] = json!(d);
        }
        // A part says so in its node's name too, for viewers that show names only.
        if let Some(k) = i.part {
            extras["part"] = json!(k);
        }
        let node_name = crate::scene::parts::display_name(&i.name, i.part);
        let mut node = json!({ "name": node_name, "mesh": mesh, "extras": extras });
        let transform = db.item_transform(i);
        if transform != Mat4::IDENTITY {
            node["matrix"] = json!(transform.to_cols_array());
        }
        nodes.push(node);
    }
    let node_ids: Vec<usize> = (0..nodes.len()).collect();
    let mut doc = json!({
        "asset": asset(),
        "scene": 0,
        "scenes": [{ "nodes": node_ids }],
        "nodes": nodes,
        "accessors": accessors,
        "bufferViews": views,
    });
    if !meshes.is_empty() {
        doc["meshes"] = json!(meshes);
        doc["materials"] = json!([plain_material()]);
    }
    if !bin.is_empty() {
        doc["buffers"] = json!([{ "byteLength": bin.len() }]);
    }
    Ok(glb(&doc, &bin))
}

/// Writes `bytes` to a new file `out` (never over an existing one), synced; removes what it
/// created if the write fails.
fn write_new(out: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    if out.exists() {
        return Err(Error::bad_file(out, "exists; choose another file"));
    }
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

/// The `.glb` container of glTF document `doc` and binary chunk `bin`: header, JSON chunk
/// (space-padded), BIN chunk (zero-padded; none when `bin` is empty).
pub fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
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
