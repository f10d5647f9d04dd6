//! What a write may do with something already at its target: the one rule behind `--force`.

/// What [`crate::build()`], [`crate::merge()`] and [`crate::Scene::write_manifest`] may do with
/// something already at their target. Nothing the program did not write is ever replaced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Overwrite {
    /// Refuse anything there (the default).
    #[default]
    Never,
    /// Replace what hdov wrote there before (a database, a generated scene's files) or an empty
    /// folder; refuse anything else (a folder of other files, a file, a link).
    Ours,
}
