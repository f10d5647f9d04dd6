//! Which entries of a node each triangle of its merged levels stands for, so that a tile client
//! can leave out the parts of a coarse level that stand for entries its view cell cannot see
//! (decision 131).
//!
//! A node's level is its entries' levels merged, welded and simplified ([`crate::lod::hlod`]).
//! Welding merges equal positions only and the simplifiers keep the positions they are given, so
//! every vertex of a node's level is, bit for bit, a full-detail vertex of an object of the
//! node's subtree under its model matrix. A vertex belongs to the entries whose subtrees hold
//! such a vertex, and a triangle to the union of its vertices' entries: drawing a triangle
//! whenever one of its entries is visible draws every triangle the hidden entries do not own
//! alone. A vertex found under no entry (none should be) belongs to all of them.

use std::collections::{BTreeMap, HashMap};

use glam::{Mat4, Vec3};

use crate::db::Database;
use crate::error::Result;
use crate::geom::Aabb;
use crate::format::tree_page::NodePage;
use crate::scene::Mesh;

/// Some triangles of a node's level, and the node's entries (indices into its entry list,
/// ascending) they stand for.
#[derive(Clone, Debug, PartialEq)]
pub struct Slice {
    pub entries: Vec<u32>,
    pub triangles: Vec<u32>,
    /// The box of the triangles' vertices (world space, as a node's levels are).
    pub bounds: Aabb,
}

/// A position's bits: welding and the simplifiers keep positions bit for bit.
type Key = [u32; 3];

fn key(p: [f32; 3]) -> Key {
    p.map(f32::to_bits)
}

/// For each `(node, level)` of `asked`, the level's triangles grouped by the entries they stand
/// for (each triangle in one slice, slices ordered by their entries). `pages`: every node's page.
/// Reads the asked levels and every base mesh's full-detail level once.
pub fn slices(db: &Database, pages: &[NodePage], asked: &[(u32, usize)]) -> Result<HashMap<(u32, usize), Vec<Slice>>> {
    let catalog = db.catalog();
    // Where each node and object hangs: its parent node and its index among the parent's entries.
    let mut parent_of: HashMap<u32, (u32, u32)> = HashMap::new();
    let mut leaf_of: Vec<Option<(u32, u32)>> = vec![None; catalog.objects.len()];
    for (n, page) in pages.iter().enumerate() {
        for (k, e) in page.node.entries.iter().enumerate() {
            let at = (n as u32, k as u32);
            match page.node.is_leaf() {
                true => leaf_of[e.child as usize] = Some(at),
                false => {
                    parent_of.insert(e.child, at);
                }
            }
        }
    }
    let levels: Vec<Mesh> =
        asked.iter().map(|&(n, l)| db.lod_mesh(&catalog.node_lods[n as usize][l])).collect::<Result<_>>()?;
    // The nodes that ask about each position.
    let mut asks: HashMap<Key, Vec<u32>> = HashMap::new();
    for (&(n, _), mesh) in asked.iter().zip(&levels) {
        for &p in &mesh.positions {
            let nodes = asks.entry(key(p)).or_default();
            if !nodes.contains(&n) {
                nodes.push(n);
            }
        }
    }
    // The entries of each asking node that hold each asked position.
    let mut owners: HashMap<(u32, Key), Vec<u32>> = HashMap::new();
    let mut by_mesh: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (o, record) in catalog.objects.iter().enumerate() {
        by_mesh.entry(record.mesh).or_default().push(o as u32);
    }
    for objects in by_mesh.values() {
        let full = db.lod_mesh(&catalog.object_lods(objects[0])[0])?;
        for &o in objects {
            let Some(mut at) = leaf_of[o as usize] else { continue };
            // The object's ancestors, each with the entry that leads down to it.
            let mut path = vec![at];
            while let Some(&up) = parent_of.get(&at.0) {
                path.push(up);
                at = up;
            }
            let model = Mat4::from_cols_array(&catalog.objects[o as usize].transform);
            for &p in &full.positions {
                let k = key(model.transform_point3(Vec3::from(p)).to_array());
                let Some(nodes) = asks.get(&k) else { continue };
                for &n in nodes {
                    if let Some(&(_, entry)) = path.iter().find(|a| a.0 == n) {
                        let set = owners.entry((n, k)).or_default();
                        if let Err(i) = set.binary_search(&entry) {
                            set.insert(i, entry);
                        }
                    }
                }
            }
        }
    }
    let mut out = HashMap::new();
    for (&(n, l), mesh) in asked.iter().zip(&levels) {
        let all: Vec<u32> = (0..pages[n as usize].node.entries.len() as u32).collect();
        let mut groups: BTreeMap<Vec<u32>, Vec<u32>> = BTreeMap::new();
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let mut entries = Vec::new();
            for &v in tri {
                match owners.get(&(n, key(mesh.positions[v as usize]))) {
                    Some(set) => entries.extend_from_slice(set),
                    None => entries.extend_from_slice(&all),
                }
            }
            entries.sort_unstable();
            entries.dedup();
            groups.entry(entries).or_default().push(t as u32);
        }
        let bounds = |triangles: &[u32]| {
            triangles.iter().flat_map(|&t| &mesh.indices[3 * t as usize..3 * t as usize + 3]).fold(Aabb::EMPTY, |b, &v| {
                b.grow(Vec3::from(mesh.positions[v as usize]))
            })
        };
        let slices = groups.into_iter().map(|(entries, triangles)| Slice { entries, bounds: bounds(&triangles), triangles });
        out.insert((n, l), slices.collect());
    }
    Ok(out)
}

/// The triangles `triangles` of `mesh` as a mesh of their own (vertices in order of first use).
pub fn slice_mesh(mesh: &Mesh, triangles: &[u32]) -> Mesh {
    let mut at = vec![u32::MAX; mesh.positions.len()];
    let mut out = Mesh::default();
    for &t in triangles {
        for &v in &mesh.indices[3 * t as usize..3 * t as usize + 3] {
            if at[v as usize] == u32::MAX {
                at[v as usize] = out.positions.len() as u32;
                out.positions.push(mesh.positions[v as usize]);
            }
            out.indices.push(at[v as usize]);
        }
    }
    out
}
