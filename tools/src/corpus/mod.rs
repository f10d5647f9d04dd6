//! Real scenes for the corpus (issue 31), converted by hdov's own readers from what the package
//! registries offer: game levels with their own visibility data ([`bsp`]).

pub mod bsp;
