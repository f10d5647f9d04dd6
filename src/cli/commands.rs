//! One function per subcommand: parse, call the library, report.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use serde_json::json;

use hdov::city::{CityParams, CityScale};
use hdov::text::{parse_box, parse_dims, parse_eye_heights, parse_matrix};
use hdov::{
    Aabb, BackendKind, BuildParams, BuildReport, Database, DovCodec, Error, EyeHeights, FloorTest, Info, InternalLods,
    LayoutKind, LodParams, Manifest, ObjectParts, Overwrite, Param, Progress, Result, Sampling, Scene, Shard,
    TreeAlgorithm, ViewGrid, VisibilityParams,
};

#[derive(Args)]
pub struct DemoArgs {
    /// Directory for the demo's scene and database. An earlier demo's output there is
    /// replaced; a directory holding anything else is refused.
    #[arg(long, default_value = "hdov-demo")]
    out: PathBuf,
    /// Print one JSON document instead of the summary.
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand)]
pub enum GenerateCommand {
    /// A synthetic city: a street grid of buildings plus instances of one dense detail model.
    City(CityArgs),
}

#[derive(Args)]
pub struct CityArgs {
    /// Output directory; the scene is written as DIR/city.json and DIR/city.meshes.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Blocks along x and z, e.g. 12x12 (overrides the scale's count).
    #[arg(long, value_parser = parse_dims::<2>)]
    blocks: Option<[u32; 2]>,
    /// tiny (~50 objects), small (~440), default (~2,200), large (~11,300, the thesis's) or huge
    /// (~115,000; its visibility needs about 20 GB: docs/sharding.md).
    #[arg(long, default_value = "default")]
    scale: CityScale,
    /// A real mesh (OBJ) to instance as the dense detail model, e.g. the Stanford bunny.
    #[arg(long)]
    detail_model: Option<PathBuf>,
    /// Replace DIR/city.json and DIR/city.meshes if they are an earlier generated scene.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
pub struct BuildArgs {
    /// The scene: a glTF 2.0 file (.gltf/.glb: each node with a mesh one object, shared meshes
    /// stored once), an OBJ file (each o/g group one object) or a scene manifest .json.
    scene: PathBuf,
    /// The database directory to create.
    #[arg(long)]
    out: PathBuf,
    /// Viewing region X0,Y0,Z0,X1,Y1,Z1, a box of cells (default: the scene's grid if it brings
    /// one, else cells only where a viewer can stand: eye height above a floor, every storey).
    #[arg(long, value_parser = parse_box, allow_hyphen_values = true)]
    region: Option<Aabb>,
    /// Cells along x, y (height layers) and z, e.g. 16x1x16.
    #[arg(long, value_parser = parse_dims::<3>, conflicts_with = "cell_size")]
    grid: Option<[u32; 3]>,
    /// Cell edge length along x and z (default: a sixteenth of the scene's longer side); cells
    /// where a viewer can stand are at most the lowest eye height tall, a --region's one layer.
    #[arg(long, allow_negative_numbers = true)]
    cell_size: Option<f32>,
    /// LOW,HIGH: the eye heights above a floor, in scene units, where cells are made when
    /// neither --region nor --grid is given and the scene brings no grid.
    #[arg(long, value_parser = parse_eye_heights, default_value = "1,2")]
    eye_heights: EyeHeights,
    /// Bytes per tree node page and V-page layout page.
    #[arg(long, default_value_t = 4096)]
    page_size: u32,
    /// Most entries per tree node (default 16, or what a page holds if fewer).
    #[arg(long)]
    fanout: Option<u32>,
    /// R-tree construction: str (bulk load) or linear (Guttman insertion, the thesis's baseline).
    #[arg(long, default_value = "str")]
    tree: TreeAlgorithm,
    /// Objects: geometry (each one far larger than a cell cut into parts of about two cells:
    /// what exporters group by material or storey spans the scene, and would be in every
    /// answer; docs/decisions.md 124) or file (the file's objects as they are).
    #[arg(long, default_value = "geometry")]
    objects: ObjectParts,
    /// Internal (tree node) LODs: hlod (levels by geometric error) or thesis (§5.6, from the
    /// children's coarsest levels, to reproduce the thesis's figures).
    #[arg(long, default_value = "hlod")]
    internal_lods: InternalLods,
    #[command(flatten)]
    visibility: VisibilityArgs,
    /// Replace an existing database (or empty directory) at --out; anything else is refused.
    #[arg(long)]
    force: bool,
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct VisibilityArgs {
    /// Texels per cube-face edge for the DoV measurement.
    #[arg(long, default_value_t = 128)]
    resolution: u32,
    /// Sample points per cell: `region` (probe:32:4:24576: the fewest wrong pixels from anywhere
    /// in a cell; docs/dov.md), `corners` (the 8 shared corners alone: the cheap option, a third
    /// to a half of region's visibility time), a number K of stratified interior points in
    /// addition to the corners, `adaptive[:SEEDS:BUDGET]`: points where new objects appear, at
    /// most BUDGET per cell, or `probe[:POINTS:RAYS[:REGION[:NEAREST]]]`: rays from POINTS
    /// points of each cell towards the objects its neighbourhood sees, RAYS per point and object
    /// (from the NEAREST points to where it was seen: fewer is faster, e.g. probe:32:4:24576:8,
    /// and may miss more), and REGION rays from all over the cell in every direction.
    #[arg(long, default_value = "region")]
    samples: Sampling,
    /// DoV backend: auto (a wgpu adapter if any, else cpu), gpu or cpu.
    #[arg(long, default_value = "auto")]
    backend: BackendKind,
    /// Compute only part I of N of the cells, keeping only their V-data (join the parts with a
    /// --no-visibility base build: `hdov merge BASE SHARDS… --out DB`).
    #[arg(long)]
    shard: Option<Shard>,
    /// With --shard: measure against the tree, LODs and catalog of this --no-visibility base
    /// build instead of building them again (the shard then costs only its cells' visibility).
    #[arg(long, requires = "shard")]
    base: Option<PathBuf>,
    /// V-page layouts to write, comma-separated [default: horizontal,vertical,indexed-vertical,
    /// leaving horizontal and vertical out where their slots for every node in every cell would
    /// take over 512 MiB; name them here to write them whatever their size].
    #[arg(long, value_delimiter = ',')]
    layouts: Option<Vec<LayoutKind>>,
    /// How V-entries store DoV: f32, or log-u16 (smaller; error bound in docs/storage-format.md).
    #[arg(long, default_value = "f32")]
    dov_codec: DovCodec,
    /// GPU backend: draw an object at a coarser LOD when its simplification error, seen from the
    /// sample point, is below this many texels (0 = always full detail). 0.05 keeps every
    /// object's DoV within 0.5 % + 2 texels of full detail (docs/dov.md); the CPU backend ignores it.
    #[arg(long, default_value_t = hdov::DEFAULT_LOD_TOLERANCE_TEXELS, allow_negative_numbers = true)]
    lod_draw_tolerance: f32,
    /// GPU backend: draw region rays as small cube maps of N² texels a face from many origins
    /// (N = 1: 6 rays an origin, as many origins as rays / 6) instead of casting them on the CPU;
    /// 0 = cast them (the reference). Fewer texels a view means more origins: more accurate, more
    /// draws (docs/dov.md, "Region views on the GPU").
    #[arg(long, default_value_t = 0)]
    region_views: u32,
    /// Visible-zero-DoV floor tests, comma-separated: box (the object's box meets the cell),
    /// box:M (within M of it), neighbours (a neighbouring cell's corner sees it), parts (a part
    /// of a cut object next to a part the cell sees, turning a face to the cell), or none. Default: box,neighbours,parts on
    /// a grid (--grid, --region, or the scene's own) or with --objects file, box,parts on cells
    /// made where viewers stand (their neighbours' corners see into other rooms); box alone with `--samples probe`
    /// without region rays (its rays check what the neighbour test would guess); with region
    /// rays the neighbours test also takes what the neighbouring cells' region rays met.
    #[arg(long, value_delimiter = ',')]
    zero_dov_floor: Vec<String>,
    /// Build the tree and LODs only, without visibility.
    #[arg(long)]
    no_visibility: bool,
}

impl VisibilityArgs {
    /// The parameters for `objects` on view cells `cells` (the default floors depend on both;
    /// `None` before the cells are made).
    fn params(&self, objects: ObjectParts, cells: Option<&ViewGrid>) -> Result<Option<VisibilityParams>> {
        if self.no_visibility {
            return Ok(None);
        }
        let zero_dov_floor = FloorTest::chosen(&self.zero_dov_floor, &self.samples, objects, cells)
            .map_err(|r| Error::bad_param(Param::ZeroDovFloor, r))?;
        Ok(Some(VisibilityParams {
            resolution: self.resolution,
            backend: self.backend,
            sampling: self.samples,
            // Unnamed: the default layouts under the default budget; named: those, whatever their size.
            layouts: self.layouts.clone().unwrap_or_else(|| VisibilityParams::default().layouts),
            slot_budget: self.layouts.is_none().then_some(hdov::DEFAULT_SLOT_BUDGET),
            dov_codec: self.dov_codec,
            shard: self.shard,
            lod_draw_tolerance: self.lod_draw_tolerance,
            region_views: self.region_views,
            zero_dov_floor,
        }))
    }
}

#[derive(Args)]
pub struct MergeArgs {
    /// The base build whose tree, LODs and catalog the shards were measured against (the same
    /// scene and parameters, built with --no-visibility).
    base: PathBuf,
    /// The shards (hdov build --shard I/N), all N of them.
    #[arg(required = true)]
    shards: Vec<PathBuf>,
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing database (or empty directory) at --out; anything else is refused.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
pub struct DovArgs {
    scene: PathBuf,
    /// The viewpoint X,Y,Z.
    #[arg(long, value_parser = hdov::text::parse_point, allow_hyphen_values = true)]
    at: glam::Vec3,
    #[arg(long, default_value_t = 256)]
    resolution: u32,
    #[arg(long, default_value = "auto")]
    backend: BackendKind,
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct InfoArgs {
    db: PathBuf,
    /// List the view cells instead: id, lattice coordinates and box, one line each (JSON lines
    /// with --json).
    #[arg(long)]
    cells: bool,
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct ExportArgs {
    db: PathBuf,
    /// The glTF binary to write (.glb); an existing file is refused.
    #[arg(long, required_unless_present = "tiles", conflicts_with = "tiles")]
    out: Option<PathBuf>,
    /// The level of detail of every object (0 = full detail; an object's coarsest where its chain
    /// is shorter).
    #[arg(long, default_value_t = 0, conflicts_with = "tiles")]
    lod: u32,
    /// Write the database as a 3D Tiles 1.1 tileset into this new directory instead: a tile per
    /// stored level, each content file once, and every view cell's visibility beside it
    /// (docs/format.md, "3D Tiles").
    #[arg(long = "3dtiles", value_name = "DIR")]
    tiles: Option<PathBuf>,
    /// The root tile's transform, 16 numbers, column-major, applied after the turn to 3D Tiles'
    /// z-up (e.g. an east-north-up frame on the globe).
    #[arg(long, value_parser = parse_matrix, allow_hyphen_values = true, requires = "tiles")]
    root_transform: Option<glam::Mat4>,
    #[arg(short, long)]
    quiet: bool,
}

pub fn export(a: ExportArgs) -> Result<()> {
    let db = Database::open(&a.db)?;
    if let Some(dir) = &a.tiles {
        let r = hdov::tiles::write_tileset(&db, dir, a.root_transform, &Progress::for_terminal(a.quiet))?;
        println!(
            "{}: {} tiles, {} content files ({:.1} MB), tileset.json and {} subtree tilesets {:.1} kB, visibility of {} cells {:.1} kB ({:.2} % of the content)",
            dir.display(),
            r.tiles,
            r.contents,
            r.content_bytes as f64 / 1e6,
            r.subtrees,
            r.tileset_bytes as f64 / 1e3,
            r.cells,
            r.visibility_bytes as f64 / 1e3,
            100.0 * r.visibility_bytes as f64 / r.content_bytes.max(1) as f64
        );
        return Ok(());
    }
    let out = a.out.expect("clap requires --out without --3dtiles");
    hdov::write_scene_glb(&db, a.lod, &out)?;
    println!("{}: {} objects at LOD {} as glTF", out.display(), db.catalog().objects.len(), a.lod);
    Ok(())
}

pub fn generate(cmd: GenerateCommand) -> Result<()> {
    let GenerateCommand::City(a) = cmd;
    let city = CityParams { seed: a.seed, blocks: a.blocks, scale: a.scale, detail_model: None };
    city.check()?;
    let path = generate_city(&a.out, city, a.detail_model.as_deref(), a.force)?;
    let (scene, _) = Scene::load(&path)?;
    println!(
        "{}: {} objects, {} base meshes, {} triangles ({} stored)",
        path.display(),
        scene.objects.len(),
        scene.meshes.len(),
        scene.triangle_count(),
        scene.stored_triangle_count()
    );
    Ok(())
}

/// Generates a city into `out/city.json` (+ `city.meshes`); `replace` lets it overwrite an
/// earlier generated scene there, never other files.
fn generate_city(out: &Path, mut city: CityParams, detail: Option<&Path>, replace: bool) -> Result<PathBuf> {
    city.detail_model = match detail {
        Some(p) => {
            let (s, _) = Scene::load(p)?;
            Some(s.merged_mesh())
        }
        None => None,
    };
    let scene = hdov::city::generate(&city)?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let path = out.join("city.json");
    scene.write_manifest(&path, overwrite(replace))?;
    Ok(path)
}

pub fn build(a: BuildArgs) -> Result<()> {
    let params = |cells: Option<&ViewGrid>| -> Result<BuildParams> {
        Ok(BuildParams {
            objects: a.objects,
            page_size: a.page_size,
            fanout: a.fanout,
            tree: a.tree,
            lod: LodParams { internal: a.internal_lods, ..Default::default() },
            visibility: a.visibility.params(a.objects, cells)?,
        })
    };
    // Every argument that does not need the scene is checked before the scene is read.
    params(None)?.check(None)?;
    let (mut scene, warnings) = Scene::load(&a.scene)?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    let grid = scene.view_grid(a.region, a.grid, a.cell_size, a.eye_heights)?;
    let params = params(Some(&grid))?;
    scene.grid = Some(grid);
    let progress = Progress::for_terminal(a.json);
    let report = match &a.visibility.base {
        Some(base) => hdov::build_shard_on(&scene, base, &a.out, &params, overwrite(a.force), &progress)?,
        None => hdov::build(&scene, &a.out, &params, overwrite(a.force), &progress)?,
    };
    report_cleaned(&report);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report).expect("serialisable"));
    } else {
        print_build(&a.out, &report);
    }
    Ok(())
}

fn print_build(out: &Path, r: &BuildReport) {
    let c = &r.manifest.counts;
    let t = &r.manifest.tree;
    println!("{}: built", out.display());
    println!(
        "  objects {} ({} base meshes), triangles {} ({} stored)",
        c.objects, c.base_meshes, c.triangles, c.stored_triangles
    );
    println!(
        "  tree {}: {} nodes, {} leaves, height {}, fan-out {}, fill {:.0} %",
        r.manifest.build.tree,
        t.nodes,
        t.leaves,
        t.height,
        t.max_entries,
        t.fill_factor * 100.0
    );
    println!("  LOD triangles {} (leaf + internal)", c.lod_triangles);
    print_visibility(&r.manifest);
    println!("  time: tree {:.2} s, LODs {:.2} s, write {:.2} s", r.tree_seconds, r.lod_seconds, r.write_seconds);
}

/// Says which leftovers of dead builds were removed or put back (on stderr: stdout may be JSON).
fn report_cleaned(report: &BuildReport) {
    if let Some(p) = &report.restored {
        eprintln!("note: put back {}, moved aside by a build that did not finish", p.display());
    }
    for p in &report.cleaned {
        eprintln!("note: removed {}, left by a build that did not finish", p.display());
    }
}

fn print_visibility(m: &Manifest) {
    let (Some(v), Some(g), Some(p)) = (&m.visibility, &m.grid, m.build.visibility.as_ref()) else {
        println!("  visibility: none");
        return;
    };
    let where_ = if g.present.is_some() { " where a viewer can stand" } else { "" };
    println!(
        "  visibility: {} of {} cells{where_} (lattice {}x{}x{}), {} sample points at R = {}, {:.1} s, backend {}",
        v.cells_computed,
        g.present_count(),
        g.dims[0],
        g.dims[1],
        g.dims[2],
        v.sample_points,
        p.resolution,
        v.seconds,
        v.backend
    );
    if let Some(phases) = &v.phases {
        println!("    phases: {phases}");
    }
    for l in &v.layouts {
        println!("    {:<17} V-pages {:>12} bytes, index {:>10} bytes", l.name, l.vpage_bytes, l.index_bytes);
    }
    for l in &v.left_out {
        println!("    {:<17} {l}", l.kind.name());
    }
}

pub fn info(a: InfoArgs) -> Result<()> {
    let db = Database::open(&a.db)?;
    if a.cells {
        return print_cells(&db, a.json);
    }
    let info = db.info()?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&info).expect("serialisable"));
        return Ok(());
    }
    print_info(&a.db, &info, db.manifest());
    Ok(())
}

/// `hdov info --cells`: every view cell, ascending ids.
fn print_cells(db: &Database, json: bool) -> Result<()> {
    let grid = db.grid().ok_or_else(|| Error::bad_file(db.dir(), "holds no viewing grid"))?;
    let mut out = std::io::stdout().lock();
    for id in grid.present_ids() {
        let cell = grid.cell_coords(id);
        // The box of the squares where its viewers stand (a quarter of its lattice cell, or
        // less where a wall cuts it), and those squares: bit z·8 + x of the lattice cell's
        // 8 × 8 (hex).
        let b = grid.view_cell(id).places_box();
        let places = format!("{:016x}", grid.places_of(id));
        let line = if json {
            serde_json::json!({ "id": id, "cell": cell, "min": b.min.to_array(), "max": b.max.to_array(), "places": places })
                .to_string()
        } else {
            format!("{id} {cell:?} {:?} {:?} {places}", b.min.to_array(), b.max.to_array())
        };
        if writeln!(out, "{line}").is_err() {
            break;
        }
    }
    Ok(())
}

fn print_info(path: &Path, info: &Info, m: &Manifest) {
    println!("{} (format v{}, {})", path.display(), info.format_version, info.created_by);
    println!(
        "  objects {} ({} base meshes), triangles {} ({} stored), LOD triangles {}",
        info.objects, info.base_meshes, info.triangles, info.stored_triangles, info.lod_triangles
    );
    println!(
        "  LOD bytes: leaf {}, internal {} ({:.2}× the leaf LODs)",
        info.leaf_lod_bytes,
        info.internal_lod_bytes,
        info.internal_lod_bytes as f64 / info.leaf_lod_bytes.max(1) as f64
    );
    let t = &info.tree;
    println!(
        "  tree {}: {} nodes, {} leaves, height {}, fan-out {}, fill {:.0} %",
        info.build.tree,
        t.nodes,
        t.leaves,
        t.height,
        t.max_entries,
        t.fill_factor * 100.0
    );
    if let Some(g) = &info.grid {
        let [nx, ny, nz] = g.dims;
        if g.sparse {
            println!(
                "  view cells {} where a viewer can stand, in a {nx}x{ny}x{nz} lattice over {:?}",
                info.cells, g.region
            );
        } else {
            println!("  grid {nx}x{ny}x{nz} = {} cells over {:?}", info.cells, g.region);
        }
    }
    for f in &info.files {
        println!("  {:<16} {:>12} bytes", f.name, f.bytes);
    }
    print_visibility(m);
    for (kind, l) in &info.layouts {
        let name = kind.name();
        println!(
            "    {name:<17} visible nodes per cell {:.1} (max {}), cell flip reads {:.1} pages (max {})",
            l.visible_nodes_per_cell.mean, l.visible_nodes_per_cell.max, l.flip_pages.mean, l.flip_pages.max
        );
    }
}

/// Resolution of the demo's DoV measurement: fine enough for the city's sphere-of-directions
/// floor (1.9e-5) and measured in about a minute on 2 CPU cores.
const DEMO_RESOLUTION: u32 = 128;

/// What a demo directory holds; anything else in it makes the demo refuse the directory.
const DEMO_FILES: [&str; 4] = ["city.json", "city.meshes", "city.hdov", "city.png"];

/// Refuses `out` unless it is missing, empty or holds nothing but an earlier demo's files
/// (each of which is replaced only if hdov wrote it).
fn check_demo_dir(out: &Path) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(out) else {
        return match std::fs::symlink_metadata(out) {
            Ok(_) => Err(Error::bad_file(out, "not a directory; choose another --out")),
            Err(_) => Ok(()),
        };
    };
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(out, e))?;
        let name = entry.file_name();
        let name_s = name.to_string_lossy();
        // `.city.hdov.tmp-PID` and the like: what a killed demo left while writing its files.
        let leftover = DEMO_FILES.iter().any(|f| name_s.starts_with(&format!(".{f}.")));
        if !leftover && !DEMO_FILES.iter().any(|f| name == *f) {
            return Err(Error::bad_file(
                out,
                format!("holds '{}', which the demo did not write; choose another --out", name.to_string_lossy()),
            ));
        }
    }
    Ok(())
}

pub fn demo(a: DemoArgs) -> Result<()> {
    let t = std::time::Instant::now();
    check_demo_dir(&a.out)?;
    let city = CityParams { seed: 1, scale: CityScale::Default, ..Default::default() };
    let scene_path = generate_city(&a.out, city, None, true)?;
    let (scene, _) = Scene::load(&scene_path)?;
    let db_path = a.out.join(DEMO_FILES[2]);
    let params = BuildParams {
        visibility: Some(VisibilityParams { resolution: DEMO_RESOLUTION, ..Default::default() }),
        ..Default::default()
    };
    if !a.json {
        let g = scene.grid.as_ref().expect("the city brings its grid");
        println!(
            "demo: default city ({} objects), grid {}x{}x{} = {} cells, DoV at R = {DEMO_RESOLUTION}",
            scene.objects.len(),
            g.dims[0],
            g.dims[1],
            g.dims[2],
            g.cell_count()
        );
    }
    let report = hdov::build(&scene, &db_path, &params, Overwrite::Ours, &Progress::for_terminal(a.json))?;
    report_cleaned(&report);
    if !a.json {
        println!("scene: {}", scene_path.display());
        print_build(&db_path, &report);
    }
    let db = Database::open(&db_path)?;
    let asked = super::query::demo_queries(&db, a.json)?;
    let picture_path = a.out.join(DEMO_FILES[3]);
    let picture = super::render::demo_picture(&db, asked.2, &picture_path)?;
    if !a.json {
        match &picture {
            Some(_) => println!(
                "picture: {} (full detail | the default answer along the walk, coloured by LOD level)",
                picture_path.display()
            ),
            None => println!("picture: skipped (no graphics adapter)"),
        }
    }
    if a.json {
        let doc = json!({
            "scene": scene_path,
            "db": db_path,
            "build": report,
            "queries": asked.0,
            "walk": asked.1,
            "picture": picture.is_some().then_some(&picture_path),
            "seconds": t.elapsed().as_secs_f64(),
            "serve": format!("hdov serve {}", db_path.display()),
        });
        println!("{}", serde_json::to_string_pretty(&doc).expect("serialisable"));
    } else {
        println!(
            "demo finished in {:.1} s; next: hdov query {} --at X,Y,Z, hdov walk {} --walk turning --fidelity",
            t.elapsed().as_secs_f64(),
            db_path.display(),
            db_path.display()
        );
        println!("walk it in a browser (http://127.0.0.1:8080/): hdov serve {}", db_path.display());
    }
    Ok(())
}

pub fn merge(a: MergeArgs) -> Result<()> {
    let m = hdov::merge(&a.base, &a.shards, &a.out, overwrite(a.force))?;
    let (cells, points) = m.visibility.as_ref().map_or((0, 0), |v| (v.cells_computed, v.sample_points));
    println!("{}: merged {} shards, {cells} cells, {points} sample points", a.out.display(), a.shards.len());
    Ok(())
}

pub fn dov(a: DovArgs) -> Result<()> {
    let (scene, warnings) = Scene::load(&a.scene)?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    let mut backend = hdov::open_backend(&scene, a.resolution, a.backend, &Default::default())?;
    let point = backend.measure(a.at)?;
    let mut objects = point.objects.clone();
    objects.sort_by(|x, y| y.1.total_cmp(&x.1));
    if a.json {
        let doc = json!({
            "at": a.at.to_array(),
            "resolution": a.resolution,
            "backend": if backend.name().starts_with("gpu") { "gpu" } else { "cpu" },
            "adapter": backend.name(),
            "sky": point.empty,
            "back_face": point.back_face,
            "objects": objects.iter().map(|&(id, d)| json!({"name": scene.objects[id as usize].name, "id": id, "dov": d})).collect::<Vec<_>>(),
        });
        println!("{}", serde_json::to_string_pretty(&doc).expect("serialisable"));
        return Ok(());
    }
    println!("DoV at {:?}, R = {}, {}", a.at.to_array(), a.resolution, backend.name());
    println!(
        "  {} objects visible, covering {:.4} of the sphere; sky {:.4}",
        objects.len(),
        point.total(),
        point.empty
    );
    for &(id, d) in &objects {
        println!("  {:>10.6}  {} (#{id})", d, scene.objects[id as usize].name);
    }
    Ok(())
}

/// `--force`: replace what hdov wrote there before, never anything else.
fn overwrite(force: bool) -> Overwrite {
    if force { Overwrite::Ours } else { Overwrite::Never }
}
