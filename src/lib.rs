//! hdov: a disk-resident Hierarchical Degree-of-Visibility (HDoV) tree database.
//!
//! Pipeline: [`scene`] (import, [`city`] generator) → [`rtree`] (bulk load) → [`lod`] (leaf and
//! internal LODs) → [`dov`] (visibility per viewing cell of a [`grid`]) → [`db`] (the database
//! directory, with V-pages written by the `hdov-storage` crate).

pub mod city;
pub mod cli;
pub mod db;
pub mod dov;
pub mod error;
pub mod geom;
pub mod grid;
pub mod lod;
pub mod progress;
pub mod rtree;
pub mod scene;

pub use error::{Error, Result};
