//! Where a walk's geometry bytes go (issue 18's walk target; the `walk-loads` tool): a session
//! walks a path, and the bytes it loaded are split into
//!
//! - *first loads*: the first record loaded of a base mesh (objects; instances share records) or
//!   of a node's chain;
//! - *refinements*: a finer record of a mesh or node that already had one loaded;
//! - the *floor*: per base mesh and node, the largest record any of the walk's answers drew,
//!   summed. A loader that knew the walk in advance and fetched each thing once, at the finest
//!   level the walk will need, would load exactly this; no loader can draw the same answers with
//!   less.

use std::collections::{HashMap, HashSet};

use glam::Vec3;
use hdov::{Database, ItemKind, SessionParams};

/// What one walk loaded, in bytes; `[objects, nodes]` where split.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Loads {
    /// Bytes loaded, as the session's steps report them.
    pub loaded: u64,
    /// First loads of each base mesh and node.
    pub first: [u64; 2],
    /// Finer records of a mesh or node already loaded.
    pub refine: [u64; 2],
    /// The largest record of each base mesh and node that an answer drew, summed.
    pub floor: [u64; 2],
}

/// Walks `path` (viewpoint, look) in a fresh session of `params` (its resident geometry must be
/// unbounded, so that nothing loaded is evicted and loaded again) and splits what it loaded.
pub fn walk(db: &Database, path: &[(Vec3, Vec3)], params: &SessionParams) -> hdov::Result<Loads> {
    let mut session = db.session(params)?;
    let mut loads = Loads::default();
    // Per (objects 0 / nodes 1, mesh or node id): the largest record drawn so far.
    let mut largest: HashMap<(usize, u32), u64> = HashMap::new();
    let mut seen = HashSet::new();
    for &(at, look) in path {
        let step = session.step(at, Some(look))?;
        loads.loaded += step.loaded_bytes;
        if !step.flipped {
            continue;
        }
        for item in &session.answer().expect("a flip sets the answer").items {
            let key = match item.kind {
                ItemKind::Object => (0, db.catalog().objects[item.id as usize].mesh),
                ItemKind::Node => (1, item.id),
            };
            let len = u64::from(item.lod_ref.len);
            let before = largest.get(&key).copied();
            largest.insert(key, before.map_or(len, |b| b.max(len)));
            if seen.insert(item.lod_ref.offset) {
                let split = if before.is_none() { &mut loads.first } else { &mut loads.refine };
                split[key.0] += len;
            }
        }
    }
    for ((k, _), len) in largest {
        loads.floor[k] += len;
    }
    Ok(loads)
}
