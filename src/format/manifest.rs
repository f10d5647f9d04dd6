//! `manifest.json`: what a database holds and how it was built. Read first on open, and checked
//! field by field: every count and name that indexes anything is validated before use.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::params::BuildParams;
use super::{FORMAT_VERSION, MANIFEST_FILE, SCENE_FILES};
use crate::error::{Error, Result};
use crate::grid::ViewGrid;
use crate::rtree::TreeStats;
use hdov_storage::LayoutKind;

/// What the visibility stage measured and wrote.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisibilityInfo {
    /// The backend that measured, with its adapter.
    pub backend: String,
    /// Cells of the grid this database holds visibility for.
    pub cells_computed: u64,
    pub sample_points: u64,
    /// Objects given the one-texel floor (visible from the cell, seen from no sample point).
    pub floored_objects: u64,
    /// Sample points left out because they lie inside geometry.
    pub skipped_points: u64,
    pub seconds: f64,
    /// Where `seconds` went; absent from manifests written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phases: Option<BakePhases>,
    pub layouts: Vec<LayoutInfo>,
    /// Layouts asked for that the slot budget left out (decision 134).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub left_out: Vec<LeftOutLayout>,
}

/// A layout asked for but not written: its slots for every (node, cell) would have taken
/// `slot_bytes`, more than the build's slot budget.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeftOutLayout {
    #[serde(rename = "name", with = "super::by_name::one")]
    pub kind: LayoutKind,
    pub slot_bytes: u64,
}

/// Why it is missing, and how to have it: what `hdov build`, `hdov info` and a refused query say.
impl std::fmt::Display for LeftOutLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "left out by the build: its slots for every node in every cell would take {} bytes (name it in \
             hdov build --layouts to write it)",
            self.slot_bytes
        )
    }
}

impl VisibilityInfo {
    /// The entry of `kind` if the slot budget left it out.
    pub fn left_out_of(&self, kind: LayoutKind) -> Option<&LeftOutLayout> {
        self.left_out.iter().find(|l| l.kind == kind)
    }
}

/// Wall seconds of the visibility stage's phases, each summed over the cells (a phase runs
/// parallel inside): where a bake's time goes. What they leave of [`VisibilityInfo::seconds`] is
/// opening the backend (its BVHs), the floors, combining the views and writing the layouts.
/// A phase a manifest does not name (one added later) reads as 0.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BakePhases {
    /// Cube maps at the cells' corners.
    pub corners: f64,
    /// The samplers' own cube maps (interior and adaptive points).
    pub points: f64,
    /// Region rays, or region views where the GPU draws them (ray probing, before the cells).
    pub region_rays: f64,
    /// Border rays around the region rays' rare finds (ray probing, before the cells).
    pub border_rays: f64,
    /// Rays aimed at candidates until each is met or has used its points (ray probing).
    pub search: f64,
    /// Rays that count which point sees each found object most (ray probing).
    pub hit_counts: f64,
    /// The found objects' DoV on their footprints (ray probing).
    pub footprints: f64,
    /// Lattice cells refined into their view cells.
    pub refine: f64,
}

/// The phases that ran, as `corners 4.0 s, region rays 5.9 s, …`.
impl std::fmt::Display for BakePhases {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ran: Vec<String> = self.named().iter().filter(|p| p.1 > 0.0).map(|(name, s)| format!("{name} {s:.1} s")).collect();
        f.write_str(&ran.join(", "))
    }
}

impl BakePhases {
    /// The phases as (name, seconds), in the order they run.
    pub fn named(&self) -> [(&'static str, f64); 8] {
        [
            ("corners", self.corners),
            ("points", self.points),
            ("region rays", self.region_rays),
            ("border rays", self.border_rays),
            ("search", self.search),
            ("hit counts", self.hit_counts),
            ("footprints", self.footprints),
            ("refine", self.refine),
        ]
    }

    /// `self` plus `o`, phase by phase (shards merged).
    pub fn add(&mut self, o: &BakePhases) {
        self.corners += o.corners;
        self.points += o.points;
        self.region_rays += o.region_rays;
        self.border_rays += o.border_rays;
        self.search += o.search;
        self.hit_counts += o.hit_counts;
        self.footprints += o.footprints;
        self.refine += o.refine;
    }
}

/// One V-page layout as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayoutInfo {
    pub name: String,
    pub vpage_bytes: u64,
    pub index_bytes: u64,
    pub files: Vec<FileEntry>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Counts {
    pub objects: u64,
    pub base_meshes: u64,
    /// Full-detail faces of every instance.
    pub triangles: u64,
    /// Full-detail faces of the base meshes (instances stored once).
    pub stored_triangles: u64,
    pub nodes: u64,
    pub cells: u64,
    /// Faces over all stored LOD levels (leaf and internal).
    pub lod_triangles: u64,
}

/// A file of the database and its size in bytes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileEntry {
    pub name: String,
    pub bytes: u64,
}

/// A view-invariant file a shard was measured against: its name, size and SHA-256. Not a crc32:
/// every page of a page file ends with the crc32 of its payload, and a crc32 over such pages
/// is the same whatever they hold (the CRC's residue), so two different trees of one shape
/// would have matched.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileChecksum {
    pub name: String,
    pub bytes: u64,
    /// Lower-case hex.
    pub sha256: String,
}

impl FileChecksum {
    /// The size and SHA-256 of `dir/name`, as a shard names it and a merge compares it.
    pub fn of(dir: &Path, name: &str) -> Result<FileChecksum> {
        use sha2::{Digest, Sha256};
        let path = dir.join(name);
        let io = |e| Error::io(&path, e);
        // Streamed: a huge scene's geometry is gigabytes.
        let mut hasher = Sha256::new();
        let bytes = std::io::copy(&mut std::fs::File::open(&path).map_err(io)?, &mut hasher).map_err(io)?;
        let sha256 = hasher.finalize().iter().map(|b| format!("{b:02x}")).collect();
        Ok(FileChecksum { name: name.into(), bytes, sha256 })
    }

    /// [`FileChecksum::of`] each of the [`SCENE_FILES`] in `dir`, in that order.
    pub fn of_scene_files(dir: &Path) -> Result<Vec<FileChecksum>> {
        SCENE_FILES.iter().map(|f| FileChecksum::of(dir, f)).collect()
    }
}

/// `manifest.json`. Its first key, `"hdov": "database"`, is the file's magic.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// The magic: always [`Manifest::MAGIC`].
    pub hdov: String,
    /// The format version ([`super::FORMAT_VERSION`] when written).
    pub format_version: u32,
    /// The hdov version that wrote it.
    pub created_by: String,
    /// How the database was built.
    pub build: BuildParams,
    /// What it holds.
    pub counts: Counts,
    /// Shape and fill of the tree.
    pub tree: TreeStats,
    /// The viewing grid, if any.
    pub grid: Option<ViewGrid>,
    /// The database's files and their sizes as written.
    pub files: Vec<FileEntry>,
    /// What the visibility stage measured and wrote (`None`: built without visibility).
    pub visibility: Option<VisibilityInfo>,
    /// A shard (`hdov build --shard`) keeps only its cells' V-data: the tree, catalog and
    /// geometry it was measured against are named here, by size and SHA-256, not stored; `hdov
    /// merge` takes them from a base build and refuses a shard whose files differ. Absent in a
    /// whole database.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_against: Option<Vec<FileChecksum>>,
}

/// The first two keys of a manifest: enough to tell an hdov database from anything else.
#[derive(Deserialize)]
struct Head {
    hdov: String,
    format_version: u32,
}

/// Whether `dir` holds an hdov database of any format version (its `manifest.json` says so).
/// The one test of what `replace` may overwrite: a user's folder never passes it.
pub fn is_database(dir: &Path) -> bool {
    let Ok(bytes) = std::fs::read(dir.join(MANIFEST_FILE)) else { return false };
    serde_json::from_slice::<Head>(&bytes).is_ok_and(|h| h.hdov == Manifest::MAGIC)
}

impl Manifest {
    /// The value of the `hdov` key that marks a database manifest.
    pub const MAGIC: &'static str = "database";

    /// The layouts the build wrote, in order: those it stores, less those the slot budget left
    /// out (decision 134). [`Manifest::check`] holds the written list to these.
    pub fn written_layouts(&self) -> Vec<LayoutKind> {
        let (Some(params), Some(v)) = (&self.build.visibility, &self.visibility) else { return Vec::new() };
        params.stored_layouts().into_iter().filter(|&k| v.left_out_of(k).is_none()).collect()
    }

    /// Reads and validates `DIR/manifest.json` (see [`Manifest::check`]).
    pub fn read(dir: &Path) -> Result<Manifest> {
        let path = dir.join(MANIFEST_FILE);
        let bytes = std::fs::read(&path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Error::bad_file(dir, "not an hdov database (no manifest.json)"),
            _ => Error::io(&path, e),
        })?;
        let head: Head =
            serde_json::from_slice(&bytes).map_err(|e| Error::bad_file(&path, format!("not an hdov manifest: {e}")))?;
        if head.hdov != Self::MAGIC {
            return Err(Error::bad_file(&path, format!("an hdov '{}' file, not a database manifest", head.hdov)));
        }
        if head.format_version != FORMAT_VERSION {
            return Err(Error::bad_file(
                &path,
                format!(
                    "database format version {}, this hdov reads version {FORMAT_VERSION}: rebuild it from its scene",
                    head.format_version
                ),
            ));
        }
        let m: Manifest =
            serde_json::from_slice(&bytes).map_err(|e| Error::bad_file(&path, format!("malformed manifest: {e}")))?;
        m.check(dir).map_err(|r| Error::bad_file(&path, r))?;
        Ok(m)
    }

    /// Checks the fields against each other and the files against their recorded sizes, so that
    /// no later read trusts a number the manifest got wrong. Returns the first violation.
    fn check(&self, dir: &Path) -> std::result::Result<(), String> {
        let c = &self.counts;
        self.build.check(self.grid.as_ref()).map_err(|e| format!("build parameters: {e}"))?;
        if c.objects == 0 || c.nodes == 0 || c.base_meshes == 0 {
            return Err(format!(
                "{} objects, {} base meshes, {} nodes: none may be 0",
                c.objects, c.base_meshes, c.nodes
            ));
        }
        if c.objects > u64::from(u32::MAX) || c.nodes > u64::from(u32::MAX) {
            return Err("more objects or nodes than 32-bit ids can name".into());
        }
        if self.tree.nodes as u64 != c.nodes {
            return Err(format!("tree has {} nodes, counts say {}", self.tree.nodes, c.nodes));
        }
        // The grid is checked with the build parameters only when they hold visibility: a
        // grid of a database without must be in bounds too before its cells are counted.
        if let Some(g) = &self.grid {
            crate::format::params::check_grid(g, 0).map_err(|e| e.to_string())?;
        }
        match &self.grid {
            Some(g) if g.cell_count() as u64 != c.cells => {
                return Err(format!("grid has {} cells, counts say {}", g.cell_count(), c.cells));
            }
            None if c.cells != 0 || self.visibility.is_some() => return Err("visibility without a grid".into()),
            _ => {}
        }
        if self.visibility.is_some() && self.build.visibility.is_none() {
            return Err("visibility results without their parameters".into());
        }
        let mut expected: Vec<&FileEntry> = self.files.iter().collect();
        let invariant = SCENE_FILES;
        match &self.measured_against {
            None => {
                if let Some(name) = invariant.iter().find(|n| !self.files.iter().any(|f| f.name == **n)) {
                    return Err(format!("lists no {name}"));
                }
            }
            Some(against) => {
                if self.build.visibility.as_ref().and_then(|v| v.shard).is_none() || self.visibility.is_none() {
                    return Err("names the files it was measured against, but is no shard with visibility".into());
                }
                let named: Vec<&str> = against.iter().map(|f| f.name.as_str()).collect();
                if named != invariant {
                    return Err(format!("measured against {named:?}, not {invariant:?}"));
                }
                if let Some(f) = self.files.iter().find(|f| invariant.contains(&f.name.as_str())) {
                    return Err(format!("a shard lists {}, which it does not keep", f.name));
                }
            }
        }
        if let (Some(v), Some(params)) = (&self.visibility, &self.build.visibility) {
            if v.cells_computed > c.cells {
                return Err(format!("{} cells computed of {}", v.cells_computed, c.cells));
            }
            let names: Vec<&str> = v.layouts.iter().map(|l| l.name.as_str()).collect();
            let built: Vec<String> = self.written_layouts().iter().map(|k| k.to_string()).collect();
            let asked = params.stored_layouts();
            let left_out: Vec<String> = v.left_out.iter().map(|l| l.kind.to_string()).collect();
            // Each layout asked for is written or left out, once (`built` is `asked` less what is
            // left out, so the counts add up only if every entry left out was asked for, once);
            // only horizontal and vertical are ever left out, only under a budget they pass,
            // beside indexed-vertical.
            let leavable = v.left_out.iter().all(|l| {
                l.kind != LayoutKind::IndexedVertical
                    && asked.contains(&LayoutKind::IndexedVertical)
                    && params.slot_budget.is_some_and(|b| l.slot_bytes > b)
            });
            if names != built || v.left_out.len() + names.len() != asked.len() || !leavable {
                return Err(format!(
                    "layouts {names:?} and those left out, {left_out:?}, are not those asked for, {asked:?}, under a slot budget of {:?}",
                    params.slot_budget
                ));
            }
            expected.extend(v.layouts.iter().flat_map(|l| &l.files));
        }
        // A file shorter or longer than written was truncated or replaced: say so by name
        // before any reader trips over it.
        for f in expected {
            if f.name.is_empty() || f.name.contains(['/', '\\']) || f.name == ".." {
                return Err(format!("file name '{}' is not a plain name", f.name));
            }
            let bytes = std::fs::metadata(dir.join(&f.name)).map_err(|e| format!("{}: {e}", f.name))?.len();
            if bytes < f.bytes {
                return Err(format!("{} is truncated: {bytes} bytes of the {} written", f.name, f.bytes));
            }
            if bytes > f.bytes {
                return Err(format!("{} has {bytes} bytes, {} were written", f.name, f.bytes));
            }
        }
        Ok(())
    }
}
