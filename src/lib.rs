//! hdov: a disk-resident Hierarchical Degree-of-Visibility (HDoV) tree database.
//!
//! A [`Scene`] (base meshes stored once, objects instancing them) is [`build()`]: an R-tree over
//! its objects, leaf and internal LODs, and for every cell of a viewing grid the degree of
//! visibility (DoV: visible solid angle / 4π) of every object and node, stored in V-pages beside
//! the tree. A [`Database`] opens the result read-only through memory maps.
//!
//! This file chooses the public face: building ([`build()`], [`merge()`], [`BuildParams`]),
//! reading ([`Database`], [`Info`]), asking ([`Database::query`], [`Session`], [`Answer`]),
//! scenes ([`Scene`], the [`city`] generator), measuring DoV at a point ([`open_backend`]) and
//! drawing answers ([`render`]). The modules behind it are private; the `internals` feature
//! makes them public for hdov's own tests, tools and benchmarks, with no promise of stability.
//! `docs/architecture.md` draws the layers.
//!
//! ```
//! use hdov::{Aabb, BackendKind, BuildParams, Database, Overwrite, Progress, Scene, ViewGrid, VisibilityParams};
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
//! hdov::build(&scene, &dir.path().join("boxes.hdov"), &params, Overwrite::Never, &Progress::hidden())?;
//!
//! let db = Database::open(&dir.path().join("boxes.hdov"))?;
//! let info = db.info()?;
//! assert_eq!(info.objects, 3);
//! assert_eq!(info.cells, 4);
//! assert_eq!(info.layouts.len(), 3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![cfg_attr(not(feature = "internals"), deny(missing_docs))]
// Without `internals`, whatever only the tests and tools use is unreachable from the face.
#![cfg_attr(not(feature = "internals"), allow(dead_code, unused_imports))]

/// Declares modules that are private unless the `internals` feature is on.
macro_rules! internal_modules {
    ($($name:ident),* $(,)?) => {
        $(
            #[cfg(feature = "internals")]
            #[doc(hidden)]
            pub mod $name;
            #[cfg(not(feature = "internals"))]
            mod $name;
        )*
    };
}

internal_modules!(
    build, camera, db, dov, error, export, format, geom, gfx, grid, lod, overwrite, progress, query, record, rng,
    rtree, scene
);

pub mod city;
pub mod render;
pub mod review;
pub mod text;

pub use build::{BuildReport, build, build_shard_on, merge::merge, objects_of};
pub use camera::Camera;
pub use db::Database;
pub use db::info::Info;
pub use dov::{DovBackend, IdCube, PointDov, open_backend};
pub use error::{Error, Param, Result};
pub use export::tiles;
pub use export::{lod_glb, scene_items, write_answer_glb, write_scene_glb};
pub use format::catalog::LodRef;
pub use format::params::{
    AdaptiveSampling, BackendKind, BuildParams, DEFAULT_FANOUT, DEFAULT_LOD_TOLERANCE_TEXELS, DEFAULT_SLOT_BUDGET,
    FloorTest, InternalLods, LodParams, ObjectParts, RayProbing, Sampling, Shard, VisibilityParams,
};
pub use format::{BakePhases, Manifest};
pub use geom::Aabb;
pub use grid::ViewGrid;
pub use hdov_storage::{CacheLimits, DovCodec, Error as StorageError, LayoutKind, PolicyKind};
pub use overwrite::Overwrite;
pub use progress::Progress;
pub use query::{
    Answer, CellVisibility, DEFAULT_ETA, Item, ItemKind, LodRule, Mode, QueryParams, QueryStats, Session,
    SessionParams, Step,
};
pub use rtree::TreeAlgorithm;
pub use scene::standable::EyeHeights;
pub use scene::{Mesh, Scene};
