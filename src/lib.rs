//! hdov: a disk-resident Hierarchical Degree-of-Visibility (HDoV) tree database.
//!
//! A [`Scene`] (base meshes stored once, objects instancing them) is [`build()`]: an R-tree over
//! its objects, leaf and internal LODs, and for every cell of a viewing grid the degree of
//! visibility (DoV: visible solid angle / 4π) of every object and node, stored in V-pages beside
//! the tree. A [`Database`] opens the result read-only through memory maps.
//!
//! Pipeline: [`scene`] (import, [`city`] generator) → [`rtree`] (bulk load) → [`lod`] (leaf and
//! internal LODs) → [`dov`] (visibility per viewing cell of a [`grid`]) → [`build`] (the writer)
//! → [`db`] (the reader; V-pages through the `hdov-storage` crate).
//!
//! ```
//! use hdov::{BuildParams, Database, Scene, VisibilityParams};
//! use hdov::dov::BackendKind;
//! use hdov::geom::Aabb;
//! use hdov::grid::ViewGrid;
//! use hdov::progress::Progress;
//! use glam::Vec3;
//!
//! // Two boxes on a ground plate (three instances of one cube mesh), and a 2 × 1 × 2 grid of
//! // viewing cells above the plate.
//! let mut scene = Scene::default();
//! scene.add_box("ground", Vec3::new(-10.0, -1.0, -10.0), Vec3::new(10.0, 0.0, 10.0));
//! scene.add_box("tower", Vec3::new(-3.0, 0.0, -3.0), Vec3::new(-1.0, 4.0, -1.0));
//! scene.add_box("shed", Vec3::new(1.0, 0.0, 1.0), Vec3::new(3.0, 2.0, 3.0));
//! scene.grid = Some(ViewGrid::new(Aabb::new(Vec3::new(-8.0, 1.5, -8.0), Vec3::new(8.0, 2.0, 8.0)), [2, 1, 2]));
//!
//! let dir = tempfile::tempdir()?;
//! let params = BuildParams {
//!     visibility: Some(VisibilityParams { resolution: 32, backend: BackendKind::Cpu, ..Default::default() }),
//!     ..Default::default()
//! };
//! hdov::build(&scene, &dir.path().join("boxes.hdov"), &params, false, &Progress::hidden())?;
//!
//! let db = Database::open(&dir.path().join("boxes.hdov"))?;
//! let info = db.info()?;
//! assert_eq!(info.objects, 3);
//! assert_eq!(info.cells, 4);
//! assert_eq!(info.layouts.len(), 3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod build;
pub mod camera;
pub mod city;
pub mod db;
pub mod dov;
pub mod error;
pub mod format;
pub mod geom;
pub mod gfx;
pub mod grid;
pub mod lod;
pub mod progress;
pub mod query;
pub mod record;
pub mod render;
pub mod review;
pub mod rtree;
pub mod scene;

pub use build::{BuildParams, BuildReport, VisibilityParams, build, merge::merge};
pub use db::Database;
pub use db::info::Info;
pub use error::{Error, Result};
pub use query::{Answer, Item, ItemKind, LodRule, Mode, QueryParams, QueryStats, Session, SessionParams, Step};
pub use scene::Scene;
