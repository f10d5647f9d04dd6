//! Upper bounds of a build. They keep every count inside its on-disk integer and a mistyped
//! argument from asking for days of work or an allocation the machine cannot make.

/// Viewing cells of a grid.
pub const MAX_CELLS: u64 = crate::grid::ViewGrid::MAX_CELLS;
/// Sample points a build measures: grid corners plus interior points of every cell.
pub const MAX_SAMPLE_POINTS: u64 = 1 << 26;
/// Interior sample points per cell.
pub const MAX_INTERIOR_SAMPLES: u32 = 4096;
/// Texels per cube-face edge: 8192 is the 2D texture size every wgpu adapter must offer,
/// and a cube map of it already holds 6 · 8192² = 403 M texels.
pub const MAX_RESOLUTION: u32 = 8192;
/// Smallest tree page: a node header, two entries and the page checksum.
pub const MIN_PAGE_SIZE: u32 = 100;
/// Largest tree page: 65,534 entries, so a node's entry count fits the V-page layouts' u16.
pub const MAX_PAGE_SIZE: u32 = 1 << 21;
/// Largest LOD-aware drawing tolerance, in texels.
pub const MAX_LOD_DRAW_TOLERANCE: f32 = 64.0;
