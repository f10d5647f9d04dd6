//! One function per subcommand: parse, call the library, report.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use serde_json::json;

use super::args::{parse_dims, parse_region};
use crate::city::{CityParams, CityScale};
use crate::db::build::BuildReport;
use crate::db::{self, BuildParams, Database};
use crate::error::{Error, Result};
use crate::geom::Aabb;
use crate::grid::ViewGrid;
use crate::progress::Progress;
use crate::rtree::TreeAlgorithm;
use crate::scene::Scene;

#[derive(Args)]
pub struct DemoArgs {
    /// Directory for the demo's scene and database (replaced if it exists).
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
    #[arg(long, default_value = "default")]
    scale: CityScale,
    /// A real mesh (OBJ) to instance as the dense detail model, e.g. the Stanford bunny.
    #[arg(long)]
    detail_model: Option<PathBuf>,
}

#[derive(Args)]
pub struct BuildArgs {
    /// The scene: an OBJ file (each o/g group one object) or a scene manifest .json.
    scene: PathBuf,
    /// The database directory to create.
    #[arg(long)]
    out: PathBuf,
    /// Viewing region X0,Y0,Z0,X1,Y1,Z1 (default: the scene's grid, or its footprint at eye height).
    #[arg(long, value_parser = parse_region)]
    region: Option<Aabb>,
    /// Cells along x, y (height layers) and z, e.g. 16x1x16.
    #[arg(long, value_parser = parse_dims::<3>, conflicts_with = "cell_size")]
    grid: Option<[u32; 3]>,
    /// Cell edge length along x and z (one height layer).
    #[arg(long)]
    cell_size: Option<f32>,
    /// Bytes per tree node page; the fan-out follows from it.
    #[arg(long, default_value_t = 4096)]
    page_size: u32,
    /// R-tree construction: str (bulk load) or linear (Guttman insertion, the thesis's baseline).
    #[arg(long, default_value = "str")]
    tree: TreeAlgorithm,
    /// Replace an existing database at --out.
    #[arg(long)]
    force: bool,
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct InfoArgs {
    db: PathBuf,
    #[arg(long)]
    json: bool,
}

pub fn generate(cmd: GenerateCommand) -> Result<()> {
    let GenerateCommand::City(a) = cmd;
    let path = generate_city(&a.out, a.seed, a.scale, a.blocks, a.detail_model.as_deref())?;
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

fn generate_city(
    out: &Path,
    seed: u64,
    scale: CityScale,
    blocks: Option<[u32; 2]>,
    detail: Option<&Path>,
) -> Result<PathBuf> {
    let detail_model = match detail {
        Some(p) => {
            let (s, _) = Scene::load(p)?;
            let parts: Vec<_> = (0..s.objects.len())
                .map(|i| crate::lod::transformed(s.object_mesh(i), &s.objects[i].transform))
                .collect();
            Some(crate::scene::Mesh::merged(&parts))
        }
        None => None,
    };
    let scene = crate::city::generate(&CityParams { seed, blocks, scale, detail_model });
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let path = out.join("city.json");
    crate::scene::manifest::write(&scene, &path)?;
    Ok(path)
}

pub fn build(a: BuildArgs) -> Result<()> {
    let (mut scene, warnings) = Scene::load(&a.scene)?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    let grid = ViewGrid::resolve(scene.bounds(), scene.grid, a.region, a.grid, a.cell_size)
        .map_err(|r| Error::bad_arg("--grid", r))?;
    scene.grid = Some(grid);
    let params = BuildParams { page_size: a.page_size, tree: a.tree, ..Default::default() };
    let report = db::build::build(&scene, &a.out, &params, a.force, &Progress::for_terminal(a.json))?;
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
    println!("  time: tree {:.2} s, LODs {:.2} s, write {:.2} s", r.tree_seconds, r.lod_seconds, r.write_seconds);
}

pub fn info(a: InfoArgs) -> Result<()> {
    let db = Database::open(&a.db)?;
    let m = &db.manifest;
    let c = &m.counts;
    if a.json {
        let doc = json!({
            "objects": c.objects,
            "triangles": c.triangles,
            "stored_triangles": c.stored_triangles,
            "base_meshes": c.base_meshes,
            "nodes": c.nodes,
            "cells": c.cells,
            "lod_triangles": c.lod_triangles,
            "grid": m.grid.map(|g| json!({"region": g.region.to_array(), "dims": g.dims})),
            "resolution": null,
            "layouts": {},
            "tree": m.tree,
            "build": m.build,
            "files": m.files,
            "format_version": m.format_version,
        });
        println!("{}", serde_json::to_string_pretty(&doc).expect("serialisable"));
        return Ok(());
    }
    println!("{} (format v{}, {})", a.db.display(), m.format_version, m.created_by);
    println!(
        "  objects {} ({} base meshes), triangles {} ({} stored), LOD triangles {}",
        c.objects, c.base_meshes, c.triangles, c.stored_triangles, c.lod_triangles
    );
    let t = &m.tree;
    println!(
        "  tree {}: {} nodes, {} leaves, height {}, fan-out {}, fill {:.0} %",
        m.build.tree,
        t.nodes,
        t.leaves,
        t.height,
        t.max_entries,
        t.fill_factor * 100.0
    );
    if let Some(g) = m.grid {
        println!(
            "  grid {}x{}x{} = {} cells over {:?}",
            g.dims[0],
            g.dims[1],
            g.dims[2],
            g.cell_count(),
            g.region.to_array()
        );
    }
    for f in &m.files {
        println!("  {:<16} {:>12} bytes", f.name, f.bytes);
    }
    Ok(())
}

pub fn demo(a: DemoArgs) -> Result<()> {
    let t = std::time::Instant::now();
    let scene_path = generate_city(&a.out, 1, CityScale::Default, None, None)?;
    let (scene, _) = Scene::load(&scene_path)?;
    let db_path = a.out.join("city.hdov");
    let report = db::build::build(&scene, &db_path, &BuildParams::default(), true, &Progress::for_terminal(a.json))?;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &json!({"scene": scene_path, "db": db_path, "build": report, "seconds": t.elapsed().as_secs_f64()})
            )
            .expect("serialisable")
        );
    } else {
        println!("scene: {}", scene_path.display());
        print_build(&db_path, &report);
        println!("demo finished in {:.1} s", t.elapsed().as_secs_f64());
    }
    Ok(())
}
