//! The crate's error type: every failure a user can cause names the file or argument and the reason.

use std::path::PathBuf;

/// Errors of the hdov library. `Display` is one line, fit for the CLI's `error: ...`.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An I/O failure on a named file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// A file whose contents are not what they must be (malformed, truncated, corrupted).
    #[error("{}: {reason}", path.display())]
    BadFile {
        /// The file (or database directory).
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A parameter that cannot be used, named as the library names it (`resolution`,
    /// `grid`, ...); a user interface maps the name to its own (the `hdov` command to a flag).
    #[error("{}: {reason}", param.name())]
    BadParam {
        /// The parameter.
        param: Param,
        /// Why it cannot be used.
        reason: String,
    },
    /// An error from the storage crate (pages, layouts).
    #[error(transparent)]
    Storage(#[from] hdov_storage::Error),
    /// No graphics adapter could run the GPU backend, or the graphics driver refused a request.
    /// Shown on one line, however many lines wgpu's own report has.
    #[error("gpu: {}", one_line(.0))]
    Gpu(String),
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Every parameter the library can refuse, in one list, so that a user interface maps each to its
/// own word for it and a compiler checks that the map is whole (the `hdov` command maps them to
/// flags). [`Param::name`] is the library's name, which [`Error::BadParam`]'s message starts
/// with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Param {
    /// A viewpoint.
    At,
    /// The DoV backend.
    Backend,
    /// The city generator's block counts.
    Blocks,
    /// The eye heights above a floor where view cells are made.
    EyeHeights,
    /// A query or session camera.
    Camera,
    /// A view cell, by id.
    Cell,
    /// The viewing cells' size.
    CellSize,
    /// How V-entries store DoV.
    DovCodec,
    /// The DoV threshold η.
    Eta,
    /// REVIEW's eyesight.
    Eyesight,
    /// Entries per tree node.
    Fanout,
    /// Fidelity against full detail (a session must have taken a step).
    Fidelity,
    /// REVIEW's field of view.
    Fov,
    /// The viewing grid.
    Grid,
    /// An id cube handed to a DoV backend.
    IdCube,
    /// The GPU backend's region views' texels per face edge.
    RegionViews,
    /// Interior sample points per cell (and the samplers that add them).
    InteriorSamples,
    /// The V-page layout to read.
    Layout,
    /// The V-page layouts to write.
    Layouts,
    /// The GPU backend's LOD-aware drawing tolerance.
    LodDrawTolerance,
    /// The leaf LOD chain's face ratio.
    LodRatio,
    /// LOD chains handed to the GPU backend.
    Lods,
    /// A near-plane distance.
    Near,
    /// A query's mode.
    Mode,
    /// Bytes per page.
    PageSize,
    /// A walk's path of viewpoints.
    Path,
    /// A point handed to a DoV backend.
    Point,
    /// REVIEW's prefetch factor.
    PrefetchK,
    /// The viewing grid's region.
    Region,
    /// Drawing an image (needs a graphics adapter).
    Render,
    /// Texels per cube-face edge.
    Resolution,
    /// REVIEW's disk-cell scale.
    ReviewBox,
    /// The matrix a 3D Tiles export puts on its root tile.
    RootTransform,
    /// Sample points handed to the per-cell combination.
    Samples,
    /// The city generator's scale.
    Scale,
    /// The scene.
    Scene,
    /// The base build a shard is measured against.
    Base,
    /// The part of the grid a build computes.
    Shard,
    /// The shard databases a merge joins.
    Shards,
    /// An image size.
    Size,
    /// The vmsse mode's pixel bound τ.
    Tau,
    /// The tree shape handed to the per-cell combination.
    TreeShape,
    /// The visible-zero-DoV floor tests.
    ZeroDovFloor,
}

impl Param {
    /// The library's name of the parameter (`resolution`, `page_size`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Param::At => "at",
            Param::Backend => "backend",
            Param::Blocks => "blocks",
            Param::EyeHeights => "eye_heights",
            Param::Camera => "camera",
            Param::Cell => "cell",
            Param::CellSize => "cell_size",
            Param::DovCodec => "dov_codec",
            Param::Eta => "eta",
            Param::Eyesight => "eyesight",
            Param::Fanout => "fanout",
            Param::Fidelity => "fidelity",
            Param::Fov => "fov",
            Param::Grid => "grid",
            Param::IdCube => "id cube",
            Param::InteriorSamples => "interior_samples",
            Param::RegionViews => "region_views",
            Param::Layout => "layout",
            Param::Layouts => "layouts",
            Param::LodDrawTolerance => "lod_draw_tolerance",
            Param::LodRatio => "lod.ratio",
            Param::Lods => "LODs",
            Param::Near => "near",
            Param::PageSize => "page_size",
            Param::Path => "path",
            Param::Point => "point",
            Param::PrefetchK => "prefetch_k",
            Param::Region => "region",
            Param::Render => "render",
            Param::Resolution => "resolution",
            Param::ReviewBox => "review_box",
            Param::Samples => "samples",
            Param::Scale => "scale",
            Param::Scene => "scene",
            Param::Base => "base",
            Param::Shard => "shard",
            Param::Shards => "shards",
            Param::Size => "size",
            Param::Mode => "mode",
            Param::RootTransform => "root_transform",
            Param::Tau => "tau",
            Param::TreeShape => "tree shape",
            Param::ZeroDovFloor => "zero_dov_floor",
        }
    }
}

impl Error {
    /// An I/O failure on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    /// A malformed, truncated or corrupted file at `path`.
    pub fn bad_file(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::BadFile { path: path.into(), reason: reason.into() }
    }
    /// A parameter, named as the library names it, that cannot be used.
    pub fn bad_param(param: Param, reason: impl Into<String>) -> Self {
        Error::BadParam { param, reason: reason.into() }
    }
}

/// `text` on one line: its non-empty lines trimmed and joined with ": ", leaving out wgpu's
/// "Caused by:" headings (a wgpu error is a heading, then its causes indented below it).
fn one_line(text: &str) -> String {
    let parts: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty() && *l != "Caused by:").collect();
    parts.join(": ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wgpu_report_reads_as_one_line() {
        let report = "Validation Error\n\nCaused by:\n  In Device::create_render_pipeline, label = 'render'\n    Color state [2] is invalid\n      Format R32Float is not renderable\n";
        let e = Error::Gpu(format!("llvmpipe on Gl: setting up the renderer: {report}"));
        assert_eq!(
            e.to_string(),
            "gpu: llvmpipe on Gl: setting up the renderer: Validation Error: In Device::create_render_pipeline, \
             label = 'render': Color state [2] is invalid: Format R32Float is not renderable"
        );
        assert_eq!(one_line("one line"), "one line");
    }
}
