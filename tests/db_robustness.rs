//! Every file of a database is validated on open and read: damage gives a one-line error that
//! names the damaged file, never a panic. One small database with visibility is built per test;
//! bounded loops of random mutations of each file then go through open and a read of everything
//! (every node, LOD mesh and V-page, and the info), and targeted damage gives the expected error.
//!
//! A damaged database that reads without an error must answer as the clean one, with two
//! exceptions no check can see: page or blob content changed with its checksums recomputed (done
//! on half the rounds, so that the decoders behind the checksums are exercised), and a manifest
//! field that only describes the build (timings, statistics, parameters used no more).

use std::fs;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use glam::Vec3;
use hdov::Overwrite;
use hdov::dov::BackendKind;
use hdov::format::catalog::{Catalog, LodRef};
use hdov::format::tree_page::NodePage;
use hdov::geom::Aabb;
use hdov::grid::ViewGrid;
use hdov::progress::Progress;
use hdov::scene::{Mesh, Scene};
use hdov::{BuildParams, Database, Info, VisibilityParams};
use hdov_storage::blob::reseal_checksums as reseal_blob_checksums;
use hdov_storage::blob::{BLOB_HEADER_LEN, RECORD_HEADER_LEN};
use hdov_storage::mutation::{Rng, mutate};
use hdov_storage::pagefile::reseal_checksums as reseal_page_checksums;
use hdov_storage::{LayoutKind, PageReader, ReadMode, VEntry};
use serde_json::{Value, json};

const TREE: &str = "tree.pages";
const GEOMETRY: &str = "geometry.blob";
const CATALOG: &str = "catalog.blob";
const MANIFEST: &str = "manifest.json";
const PAGE_SIZE: usize = 256;

/// The shared test town (`hdov_testkit::scenes::town`) under a grid of `dims` cells.
fn town(n: usize, dims: [u32; 3]) -> Scene {
    let mut scene = hdov_testkit::scenes::town(n, 2);
    let extent = n as f32 * 20.0;
    let region = Aabb::new(Vec3::new(-2.0, 1.5, -2.0), Vec3::new(extent - 1.0, 2.0, extent - 1.0));
    scene.grid = Some(ViewGrid::new(region, dims));
    scene
}

/// Everything a database answers, read in full.
#[derive(Debug, PartialEq)]
struct Answers {
    nodes: Vec<NodePage>,
    catalog: Catalog,
    meshes: Vec<Mesh>,
    layouts: Vec<LayoutAnswers>,
    info: Info,
}

/// One layout read in full: the visible V-pages `verify` counted, and every V-page (by cell,
/// then node).
#[derive(Debug, PartialEq)]
struct LayoutAnswers {
    kind: LayoutKind,
    visible: u64,
    vpages: Vec<Option<Vec<VEntry>>>,
}

impl Answers {
    /// Whether everything but what the manifest only describes (timings, counts of triangles,
    /// tree statistics, the build's parameters) is the same.
    fn same_data(&self, other: &Answers) -> bool {
        self.nodes == other.nodes
            && self.catalog == other.catalog
            && self.meshes == other.meshes
            && self.layouts == other.layouts
    }
}

/// Opens the database and reads every node, every LOD mesh, the info and every layout in full,
/// the tree and the layouts read in `mode`.
fn read_all(dir: &Path, mode: ReadMode) -> hdov::Result<Answers> {
    let db = Database::open_with(dir, mode)?;
    let nodes = (0..db.node_count()).map(|id| db.node(id)).collect::<hdov::Result<Vec<_>>>()?;
    let catalog = db.catalog().clone();
    let meshes = catalog
        .mesh_lods
        .iter()
        .chain(&catalog.node_lods)
        .flatten()
        .map(|l| db.lod_mesh(l))
        .collect::<hdov::Result<Vec<_>>>()?;
    let info = db.info()?;
    let mut layouts = Vec::new();
    for kind in db.layouts() {
        let layout = db.layout(kind)?;
        let visible = layout.verify()?;
        let (mut cursor, mut pages) = (layout.cursor(), PageReader::uncached());
        let mut vpages = Vec::new();
        for cell in 0..layout.cell_count() {
            cursor.flip_to_cell(cell, &mut pages)?;
            for node in 0..layout.node_count() {
                vpages.push(cursor.vpage(node, 0.0, &mut pages)?);
            }
        }
        layouts.push(LayoutAnswers { kind, visible, vpages });
    }
    Ok(Answers { nodes, catalog, meshes, layouts, info })
}

/// [`read_all`] with a panic turned into an `Err` carrying the panic's message.
fn read_all_caught(dir: &Path, mode: ReadMode) -> Result<hdov::Result<Answers>, String> {
    catch_unwind(AssertUnwindSafe(|| read_all(dir, mode))).map_err(|p| {
        p.downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default()
    })
}

/// The clean database, built once per test.
struct Fixture {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
    clean: Answers,
}

/// Builds the small town with visibility (CPU backend, R = 16, 256-byte pages) into `dir`.
fn build(dir: &Path, dims: [u32; 3]) {
    let params = BuildParams {
        page_size: PAGE_SIZE as u32,
        visibility: Some(VisibilityParams { resolution: 16, backend: BackendKind::Cpu, ..Default::default() }),
        ..Default::default()
    };
    hdov::build(&town(5, dims), dir, &params, Overwrite::Never, &Progress::hidden()).unwrap();
}

fn fixture() -> Fixture {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("db");
    build(&dir, [3, 1, 3]);
    let clean = read_all(&dir, ReadMode::Mmap).unwrap();
    assert_eq!(read_all(&dir, ReadMode::Pread).unwrap(), clean);
    assert!(clean.nodes.len() >= 5 && clean.nodes.iter().any(|n| n.node.level >= 2), "a tree of several levels");
    assert_eq!(clean.layouts.len(), 3);
    assert!(clean.layouts.iter().all(|l| l.visible > 0), "every layout holds visible V-pages");
    Fixture { _tmp: tmp, dir, clean }
}

fn layout_files() -> Vec<&'static str> {
    LayoutKind::ALL.iter().flat_map(|k| k.file_names().iter().copied()).collect()
}

/// What one damaged database gave.
#[derive(Debug, Default)]
struct Tally {
    /// An error naming the damaged file.
    errors: usize,
    /// Errors of rounds with checksums recomputed that are neither checksum errors nor the
    /// manifest's size check: the decoders behind the checksums found the damage.
    decoder_errors: usize,
    /// Everything read, the same as from the clean database.
    same: usize,
    /// Everything read, differing from the clean database: damage no check can see (checksums
    /// recomputed over changed content, or a manifest field that only describes the build).
    different: usize,
}

/// Copies the clean database into a fresh directory under `work`, with `file` replaced by
/// `bytes` (and its new size recorded in the manifest if `record_size`), and reads it all in
/// `mode`.
fn probe(
    f: &Fixture,
    work: &Path,
    file: &str,
    bytes: &[u8],
    record_size: bool,
    mode: ReadMode,
) -> Result<hdov::Result<Answers>, String> {
    let dir = work.join("db");
    if dir.exists() {
        fs::remove_dir_all(&dir).unwrap();
    }
    fs::create_dir(&dir).unwrap();
    for e in fs::read_dir(&f.dir).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), dir.join(e.file_name())).unwrap();
    }
    fs::write(dir.join(file), bytes).unwrap();
    if record_size {
        record_sizes(&dir);
    }
    read_all_caught(&dir, mode)
}

/// Memory maps on even rounds, `pread` on odd ones.
fn mode_of(round: usize) -> ReadMode {
    if round.is_multiple_of(2) { ReadMode::Mmap } else { ReadMode::Pread }
}

impl Tally {
    /// Counts one outcome and checks it: an error must be one line naming one of `names`;
    /// answers must be the clean ones unless `may_differ` allows them. Returns a violation.
    fn judge(
        &mut self,
        clean: &Answers,
        outcome: Result<hdov::Result<Answers>, String>,
        names: &[&str],
        resealed: bool,
        may_differ: impl Fn(&Answers) -> bool,
    ) -> Option<String> {
        match outcome {
            Err(panic) => Some(format!("panicked: {panic}")),
            Ok(Err(e)) => {
                self.errors += 1;
                let msg = e.to_string();
                if resealed && !msg.contains("checksum") && !msg.contains(MANIFEST) {
                    self.decoder_errors += 1;
                }
                (msg.contains('\n') || !names.iter().any(|n| msg.contains(n)))
                    .then(|| format!("error not one line naming {names:?}: {msg}"))
            }
            Ok(Ok(a)) if a == *clean => {
                self.same += 1;
                None
            }
            Ok(Ok(a)) => {
                self.different += 1;
                (!may_differ(&a)).then(|| "read without an error, answers differ from the clean database's".into())
            }
        }
    }
}

/// `rounds` random mutations of `file` (a page or blob file), checksums recomputed on every
/// other round, the file's new size recorded in the manifest on every other pair of rounds (so
/// that a truncation reaches the file's own checks), memory maps on every other pair too.
/// Without the checksums recomputed the answers must be the clean ones or an error.
fn binary_rounds(f: &Fixture, file: &str, names: &[&str], rounds: usize, seed: u64) -> Tally {
    let work = tempfile::tempdir().unwrap();
    let good = fs::read(f.dir.join(file)).unwrap();
    let mut rng = Rng(seed);
    let mut tally = Tally::default();
    let mut violations = Vec::new();
    for round in 0..rounds {
        let (mut bytes, what) = mutate(&mut rng, &good);
        let resealed = round.is_multiple_of(2);
        if resealed {
            if file.ends_with(".blob") {
                reseal_blob_checksums(&mut bytes);
            } else {
                reseal_page_checksums(&mut bytes);
            }
        }
        let outcome = probe(f, work.path(), file, &bytes, round % 4 >= 2, mode_of(round / 4));
        if let Some(v) = tally.judge(&f.clean, outcome, names, resealed, |_| resealed) {
            violations.push(format!("{file} round {round} ({what}, resealed: {resealed}): {v}"));
        }
    }
    assert!(violations.is_empty(), "{} violations:\n{}", violations.len(), violations.join("\n"));
    eprintln!("{file}: {tally:?}");
    tally
}

/// Both outcomes occur a sane number of times, and the decoders behind the checksums see some
/// of the damage: the loop probes them, not only the checksums.
fn assert_not_vacuous(t: &Tally, rounds: usize) {
    assert!(t.errors > rounds / 2, "{t:?}");
    assert!(t.same + t.different > rounds / 30, "{t:?}");
    assert!(t.decoder_errors > rounds / 10, "{t:?}");
}

#[test]
fn random_mutations_of_tree_pages() {
    let f = fixture();
    let t = binary_rounds(&f, TREE, &[TREE], 150, 0x7EEE);
    assert_not_vacuous(&t, 150);
}

#[test]
fn random_mutations_of_catalog_blob() {
    let f = fixture();
    let t = binary_rounds(&f, CATALOG, &[CATALOG], 150, 0xCA7A);
    assert_not_vacuous(&t, 150);
}

#[test]
fn random_mutations_of_geometry_blob() {
    let f = fixture();
    let t = binary_rounds(&f, GEOMETRY, &[GEOMETRY], 150, 0x6E0);
    assert_not_vacuous(&t, 150);
}

#[test]
fn random_mutations_of_layout_files() {
    let f = fixture();
    let mut total = Tally::default();
    for (i, file) in layout_files().into_iter().enumerate() {
        // Damage to a layout's index surfaces as a bad V-page read: any file of the layout.
        let kind = LayoutKind::ALL.into_iter().find(|k| k.file_names().contains(&file)).unwrap();
        let t = binary_rounds(&f, file, kind.file_names(), 60, 0x1A70 + i as u64);
        total.errors += t.errors;
        total.decoder_errors += t.decoder_errors;
        total.same += t.same;
        total.different += t.different;
    }
    assert_not_vacuous(&total, 300);
}

/// The JSON pointers of every leaf of `v` (numbers, strings, booleans, nulls).
fn leaves(v: &Value, at: String, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => m.iter().for_each(|(k, x)| leaves(x, format!("{at}/{k}"), out)),
        Value::Array(a) => a.iter().enumerate().for_each(|(i, x)| leaves(x, format!("{at}/{i}"), out)),
        _ => out.push(at),
    }
}

/// Fields that count or index something, or name files and layouts.
const INDEXING: &[&str] = &[
    "/counts/nodes",
    "/counts/objects",
    "/counts/base_meshes",
    "/counts/cells",
    "/tree/nodes",
    "/grid/dims/0",
    "/grid/dims/1",
    "/grid/dims/2",
    "/build/page_size",
    "/build/visibility/shard",
    "/build/visibility/layouts",
    "/build/visibility/layouts/1",
    "/build/visibility/resolution",
    "/visibility/layouts",
    "/visibility/layouts/0/name",
    "/visibility/layouts/2/files/1/bytes",
    "/visibility/cells_computed",
    "/files/0/bytes",
    "/files/1/bytes",
    "/files/2/bytes",
    "/files/1/name",
    "/files",
    "/grid",
];

/// A structured damage: one field (an indexing one half the time) set to an extreme, an
/// off-by-one or a value of the wrong type, or removed.
fn mutate_json(rng: &mut Rng, good: &Value) -> (Value, String) {
    let mut v = good.clone();
    let pointer = if rng.below(2) == 0 {
        INDEXING[rng.below(INDEXING.len())].to_string()
    } else {
        let mut all = Vec::new();
        leaves(good, String::new(), &mut all);
        all.swap_remove(rng.below(all.len()))
    };
    let old = v.pointer(&pointer).cloned().unwrap_or(Value::Null);
    let n = old.as_i64().unwrap_or(1);
    let new = match rng.below(14) {
        0 => json!(0),
        1 => json!(u64::MAX),
        2 => json!(-1),
        3 => json!(1e300),
        4 => json!(n + 1),
        5 => json!(n - 1),
        6 => json!(u64::from(u32::MAX) + 1),
        7 => json!("7"),
        8 => Value::Null,
        9 => json!([]),
        10 => json!({}),
        11 => json!([3, 3]),
        12 => json!(true),
        _ => {
            // Removed.
            let (parent, key) = pointer.rsplit_once('/').unwrap();
            match v.pointer_mut(parent) {
                Some(Value::Object(m)) => {
                    m.remove(key);
                }
                Some(Value::Array(a)) => {
                    if let Ok(i) = key.parse::<usize>()
                        && i < a.len()
                    {
                        a.remove(i);
                    }
                }
                _ => {}
            }
            return (v, format!("{pointer} removed"));
        }
    };
    let what = format!("{pointer}: {old} -> {new}");
    if let Some(slot) = v.pointer_mut(&pointer) {
        *slot = new;
    }
    (v, what)
}

/// Damage to the text: the byte mutations, or one digit changed to another.
fn mutate_text(rng: &mut Rng, good: &[u8]) -> (Vec<u8>, String) {
    if rng.below(3) > 0 {
        return mutate(rng, good);
    }
    let digits: Vec<usize> = (0..good.len()).filter(|&i| good[i].is_ascii_digit()).collect();
    let at = digits[rng.below(digits.len())];
    let mut b = good.to_vec();
    b[at] = b'0' + ((b[at] - b'0' + 1 + rng.below(9) as u8) % 10);
    let what = format!("digit at {at}: {} -> {}", good[at] as char, b[at] as char);
    (b, what)
}

#[test]
fn random_mutations_of_the_manifest() {
    let f = fixture();
    let work = tempfile::tempdir().unwrap();
    let good = fs::read(f.dir.join(MANIFEST)).unwrap();
    let good_json: Value = serde_json::from_slice(&good).unwrap();
    let mut rng = Rng(0x3A41);
    let mut text = Tally::default();
    let mut structured = Tally::default();
    let mut violations = Vec::new();
    // Damage to the manifest may change what it only describes; what is read from the other
    // files must stay the same.
    let clean = &f.clean;
    for round in 0..300usize {
        let (bytes, what, tally) = if round.is_multiple_of(2) {
            let (b, what) = mutate_text(&mut rng, &good);
            (b, what, &mut text)
        } else {
            let (v, what) = mutate_json(&mut rng, &good_json);
            (serde_json::to_vec_pretty(&v).unwrap(), what, &mut structured)
        };
        let outcome = probe(&f, work.path(), MANIFEST, &bytes, false, mode_of(round / 2));
        if let Some(v) = tally.judge(clean, outcome, &[MANIFEST], false, |a| a.same_data(clean)) {
            violations.push(format!("{MANIFEST} round {round} ({what}): {v}"));
        }
    }
    assert!(violations.is_empty(), "{} violations:\n{}", violations.len(), violations.join("\n"));
    eprintln!("{MANIFEST} text: {text:?}\n{MANIFEST} structured: {structured:?}");
    for t in [&text, &structured] {
        assert!(t.errors > 75 && t.same + t.different > 5, "{t:?}");
    }
}

// Targeted damage, each with the error it must give.

/// Copies the clean database into a fresh directory and applies `edit` to `file`.
fn damaged(f: &Fixture, file: &str, edit: impl FnOnce(&mut Vec<u8>)) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    for e in fs::read_dir(&f.dir).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), tmp.path().join(e.file_name())).unwrap();
    }
    let path = tmp.path().join(file);
    let mut bytes = fs::read(&path).unwrap();
    edit(&mut bytes);
    fs::write(&path, bytes).unwrap();
    tmp
}

/// Rewrites the manifest's recorded file sizes to the files' sizes now, so that damage that
/// changes a file's length reaches the file's own checks.
fn record_sizes(dir: &Path) {
    let path = dir.join(MANIFEST);
    let mut m: Value = serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
    let fix = |files: &mut Value| {
        for e in files.as_array_mut().unwrap() {
            let len = fs::metadata(dir.join(e["name"].as_str().unwrap())).unwrap().len();
            e["bytes"] = json!(len);
        }
    };
    fix(&mut m["files"]);
    for l in m["visibility"]["layouts"].as_array_mut().unwrap() {
        fix(&mut l["files"]);
    }
    fs::write(&path, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
}

/// The manifest with `edit` applied to its JSON.
fn damaged_manifest(f: &Fixture, edit: impl FnOnce(&mut Value)) -> tempfile::TempDir {
    damaged(f, MANIFEST, |b| {
        let mut m: Value = serde_json::from_slice(b).unwrap();
        edit(&mut m);
        *b = serde_json::to_vec_pretty(&m).unwrap();
    })
}

/// The one-line error of reading `dir` in full (a panic fails the test).
fn error_of(dir: &Path, what: &str) -> String {
    let e =
        read_all_caught(dir, ReadMode::Mmap).unwrap().err().unwrap_or_else(|| panic!("{what}: no error")).to_string();
    assert!(!e.contains('\n'), "{e}");
    e
}

#[test]
fn tree_page_with_a_child_out_of_range_names_the_node() {
    let f = fixture();
    let nodes = f.clean.nodes.len();
    for level in [0, 1] {
        let id = f.clean.nodes.iter().position(|n| n.node.level == level).unwrap();
        let d = damaged(&f, TREE, |b| {
            // Entry 1's child of page `id` (page 0 of the file is its header).
            let at = (1 + id) * PAGE_SIZE + 32 + 32 + 24;
            b[at..at + 4].copy_from_slice(&(if level == 0 { 1_000_000u32 } else { nodes as u32 }).to_le_bytes());
            reseal_page_checksums(b);
        });
        let e = error_of(d.path(), "child out of range");
        assert!(
            e.contains("tree.pages:") && e.contains(&format!("node {id}: entry 1")) && e.contains("out of range"),
            "{e}"
        );
        // The database opens: the node is refused when read.
        let db = Database::open(d.path()).unwrap();
        assert_eq!(db.node(id as u32).unwrap_err().to_string(), e);
    }
    // A parent pointer out of range.
    let d = damaged(&f, TREE, |b| {
        b[PAGE_SIZE + 4..PAGE_SIZE + 8].copy_from_slice(&(nodes as u32).to_le_bytes());
        reseal_page_checksums(b);
    });
    let e = error_of(d.path(), "parent out of range");
    assert!(e.contains("tree.pages:") && e.contains("node 0: parent"), "{e}");
    // In range, but pointing back up: a loop, refused by the depth-first numbering.
    let d = damaged(&f, TREE, |b| {
        b[PAGE_SIZE + 32 + 24..PAGE_SIZE + 32 + 28].copy_from_slice(&0u32.to_le_bytes());
        reseal_page_checksums(b);
    });
    let e = error_of(d.path(), "child pointing back");
    assert!(e.contains("tree.pages:") && e.contains("node 0: entry 0 points to node 0, which does not follow"), "{e}");
    let last = nodes - 1;
    let d = damaged(&f, TREE, |b| {
        let at = (1 + last) * PAGE_SIZE + 4;
        b[at..at + 4].copy_from_slice(&(last as u32).to_le_bytes());
        reseal_page_checksums(b);
    });
    let e = error_of(d.path(), "parent not preceding");
    assert!(e.contains(&format!("node {last}: parent {last} does not precede")), "{e}");
}

#[test]
fn catalog_reference_beyond_the_geometry_is_refused_on_open() {
    let f = fixture();
    let geometry_len = fs::metadata(f.dir.join(GEOMETRY)).unwrap().len();
    type Edit = Box<dyn Fn(&mut LodRef)>;
    let cases: Vec<(&str, Edit)> = vec![
        ("past the end", Box::new(move |l| l.offset = geometry_len)),
        ("overflowing", Box::new(|l| l.offset = u64::MAX - 2)),
        ("running past the end", Box::new(move |l| l.len = geometry_len as u32)),
    ];
    for (what, edit) in cases {
        let d = damaged(&f, CATALOG, |b| {
            let mut catalog = f.clean.catalog.clone();
            edit(&mut catalog.node_lods[1][0]);
            let record = bincode::serde::encode_to_vec(&catalog, bincode::config::standard()).unwrap();
            let mut blob = b[..BLOB_HEADER_LEN].to_vec();
            blob[16..24].copy_from_slice(&((RECORD_HEADER_LEN + record.len()) as u64).to_le_bytes());
            blob.extend_from_slice(&(record.len() as u32).to_le_bytes());
            blob.extend_from_slice(&[0; 4]);
            blob.extend_from_slice(&record);
            reseal_blob_checksums(&mut blob);
            *b = blob;
        });
        record_sizes(d.path());
        let e = Database::open(d.path()).err().expect(what).to_string();
        assert!(e.contains("catalog.blob:") && e.contains("outside geometry.blob"), "{what}: {e}");
    }
}

#[test]
fn manifest_counts_sizes_and_shard_are_checked() {
    let f = fixture();
    let nodes = f.clean.nodes.len() as u64;
    type Edit = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(&str, Edit, &[&str])> = vec![
        ("nodes + 1", Box::new(move |m| m["counts"]["nodes"] = json!(nodes + 1)), &["manifest.json:", "nodes"]),
        (
            "nodes + 1, in the tree's statistics too",
            Box::new(move |m| {
                m["counts"]["nodes"] = json!(nodes + 1);
                m["tree"]["nodes"] = json!(nodes + 1);
            }),
            &["tree.pages:", "manifest.json says"],
        ),
        ("nodes - 1", Box::new(move |m| m["counts"]["nodes"] = json!(nodes - 1)), &["manifest.json:", "nodes"]),
        (
            "objects + 1",
            Box::new(|m| m["counts"]["objects"] = json!(m["counts"]["objects"].as_u64().unwrap() + 1)),
            &["catalog.blob:", "manifest.json"],
        ),
        ("cells + 1", Box::new(|m| m["counts"]["cells"] = json!(10)), &["manifest.json:", "cells"]),
        ("tree.pages bytes", Box::new(|m| m["files"][0]["bytes"] = json!(1)), &["manifest.json:", "tree.pages has"]),
        (
            "a layout file's bytes",
            Box::new(|m| m["visibility"]["layouts"][1]["files"][0]["bytes"] = json!(0)),
            &["manifest.json:", "vindex.vertical has"],
        ),
        (
            "shard [3, 3]",
            Box::new(|m| m["build"]["visibility"]["shard"] = json!([3, 3])),
            &["manifest.json:", "0 ≤ I < N"],
        ),
        (
            "shard [0, 0]",
            Box::new(|m| m["build"]["visibility"]["shard"] = json!([0, 0])),
            &["manifest.json:", "0 ≤ I < N"],
        ),
        ("page size", Box::new(|m| m["build"]["page_size"] = json!(512)), &["tree.pages:", "manifest.json says 512"]),
        ("page size 0", Box::new(|m| m["build"]["page_size"] = json!(0)), &["manifest.json:", "page_size"]),
        (
            "grid dims",
            Box::new(|m| m["grid"]["dims"] = json!([u32::MAX, u32::MAX, u32::MAX])),
            &["manifest.json:", "grid"],
        ),
        (
            "a grid of 2^64 cells without visibility",
            Box::new(|m| {
                m["grid"]["dims"] = json!([1u32 << 22, 1u32 << 21, 1u32 << 21]);
                m["counts"]["cells"] = json!(0);
                m["build"]["visibility"] = Value::Null;
                m["visibility"] = Value::Null;
            }),
            &["manifest.json:", "grid"],
        ),
        (
            "a layout's file named outside the database",
            Box::new(|m| m["visibility"]["layouts"][0]["files"][0]["name"] = json!("../manifest.json")),
            &["manifest.json:", "not a plain name"],
        ),
    ];
    for (what, edit, expect) in cases {
        let d = damaged_manifest(&f, edit);
        let e = error_of(d.path(), what);
        assert!(expect.iter().all(|x| e.contains(x)), "{what}: expected {expect:?} in: {e}");
    }
}

#[test]
fn truncated_geometry_is_refused_on_open() {
    let f = fixture();
    let d = damaged(&f, GEOMETRY, |b| b.truncate(b.len() - 1));
    let e = Database::open(d.path()).err().unwrap().to_string();
    assert!(e.contains("manifest.json:") && e.contains("geometry.blob is truncated"), "{e}");
    // With the manifest agreeing, the blob's own header refuses it.
    record_sizes(d.path());
    let e = Database::open(d.path()).err().unwrap().to_string();
    assert!(e.contains("geometry.blob: truncated"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn layout_of_another_grid_is_refused() {
    let f = fixture();
    let other = tempfile::tempdir().unwrap();
    build(&other.path().join("db"), [2, 1, 2]);
    for kind in LayoutKind::ALL {
        // Consistent in itself and the right size on record, but for 4 cells, not 9.
        let d = damaged(&f, MANIFEST, |_| {});
        for file in kind.file_names() {
            fs::copy(other.path().join("db").join(file), d.path().join(file)).unwrap();
        }
        record_sizes(d.path());
        let e = error_of(d.path(), kind.name());
        let expect = format!("{}: {kind} layout has 4 cells, the grid 9", kind.file_names()[0]);
        assert!(e.contains(&expect), "{e}");
    }
}
