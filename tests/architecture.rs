//! The house as drawn in docs/architecture.md: every module of the library imports only modules
//! of lower layers (read from its `crate::` paths, comments left out), the command line only the
//! library's face, and the storage crate nothing of the library. A new module must be given its
//! layer here and in the picture.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Layers, bottom first: a module may import the modules of lower layers only (not those of its
/// own layer, nor above). The same table is drawn in docs/architecture.md.
const LAYERS: &[&[&str]] = &[
    &["error", "geom", "overwrite", "progress", "rng"],
    &["record", "grid", "camera", "rtree"],
    &["scene"],
    &["format", "city", "gfx"],
    &["lod"],
    &["dov"],
    &["db"],
    &["build", "query"],
    &["review", "render", "export", "text"],
];

/// The modules on the library's public face (the rest is private without `internals`): declared
/// `pub mod`, or re-exported whole from a private one (`pub use export::tiles;`).
const PUBLIC_MODULES: &[&str] = &["city", "render", "review", "text", "tiles"];

/// Whether `path` (after `hdov::`) names a root function such as `build(` or `open_backend(`.
fn is_function(path: &str) -> bool {
    let name: String = path.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
    path[name.len()..].starts_with('(')
}

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `text` without `//` comments (doc comments included) and string literals, so that prose and
/// messages naming a module do not count as imports.
fn code_of(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let mut in_string = false;
        let mut prev = '\0';
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i < chars.len() {
            let c = chars[i];
            if !in_string && c == '/' && chars.get(i + 1) == Some(&'/') {
                break;
            }
            if c == '"' && prev != '\\' {
                in_string = !in_string;
            } else if !in_string {
                out.push(c);
            }
            prev = c;
            i += 1;
        }
        out.push('\n');
    }
    out
}

/// The top-level modules that `code` names through `crate::` paths, including grouped imports
/// such as `use crate::{db::Database, error::{Error, Result}}`.
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        let before = rest[..at].chars().last();
        rest = &rest[at + "crate::".len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue; // e.g. `hdov_crate::`
        }
        let rest_trim = rest.trim_start();
        if let Some(group) = rest_trim.strip_prefix('{') {
            // The names at the group's top level (depth 0) start each comma-separated part.
            let mut depth = 0;
            let mut part_start = true;
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => part_start = true,
                    c if part_start && (c.is_alphanumeric() || c == '_') => {
                        let name: String =
                            group[i..].chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                        found.insert(name);
                        part_start = false;
                    }
                    _ => {}
                }
            }
        } else {
            let name: String = rest_trim.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            found.insert(name);
        }
    }
    found
}

/// The top-level module a file of `src/` belongs to (`src/dov/cpu/mod.rs` → `dov`).
fn module_of(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap();
    let first = rel.components().next().unwrap().as_os_str().to_string_lossy().into_owned();
    first.trim_end_matches(".rs").to_string()
}

#[test]
fn modules_import_only_lower_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut violations = Vec::new();
    let mut modules = BTreeSet::new();
    for file in &files {
        let module = module_of(&src, file);
        if module == "lib" || module == "main" || module == "cli" {
            continue;
        }
        modules.insert(module.clone());
        let Some(layer) = layer_of(&module) else {
            violations.push(format!("{module} ({}) has no layer in LAYERS", file.display()));
            continue;
        };
        let code = code_of(&std::fs::read_to_string(file).unwrap());
        for used in crate_paths(&code) {
            // Root re-exports of the error type are the error module's.
            if used == module || used == "Error" || used == "Result" {
                continue;
            }
            match layer_of(&used) {
                Some(l) if l < layer => {}
                Some(l) => violations.push(format!(
                    "{}: {module} (layer {layer}) imports {used} (layer {l})",
                    file.strip_prefix(&src).unwrap().display()
                )),
                None => violations.push(format!("{}: imports crate::{used}, which has no layer", file.display())),
            }
        }
    }
    assert!(violations.is_empty(), "imports against docs/architecture.md:\n{}", violations.join("\n"));
    // Every layer named is a module that exists (the table stays true to the tree).
    for m in LAYERS.iter().flat_map(|l| l.iter()) {
        assert!(modules.contains(*m), "LAYERS names {m}, which src/ does not have");
    }
}

#[test]
fn the_command_line_uses_the_library_face_only() {
    let cli = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/cli");
    let mut files = vec![Path::new(env!("CARGO_MANIFEST_DIR")).join("src/main.rs")];
    rust_files(&cli, &mut files);
    for file in files {
        let code = code_of(&std::fs::read_to_string(&file).unwrap());
        // `crate::` in the binary means the binary itself: only its own `cli` module.
        for used in crate_paths(&code) {
            assert_eq!(used, "cli", "{} reaches crate::{used}", file.display());
        }
        // The face: root items and the public modules, never the storage crate beneath it
        // (`.ci/run` also builds the command without the `internals` feature).
        assert!(!code.contains("hdov_storage"), "{} reaches the storage crate", file.display());
        for (at, _) in code.match_indices("hdov::") {
            let module: String = code[at + 6..].chars().take_while(|c| c.is_ascii_lowercase() || *c == '_').collect();
            assert!(
                module.is_empty() || PUBLIC_MODULES.contains(&module.as_str()) || is_function(&code[at + 6..]),
                "{} reaches hdov::{module}, not on the face",
                file.display()
            );
        }
    }
    let lib = code_of(&std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("src/lib.rs")).unwrap());
    assert!(!lib.contains("mod cli"), "the library must not contain the command line");
    for m in PUBLIC_MODULES {
        let reexported =
            lib.lines().any(|l| l.trim().starts_with("pub use ") && l.trim().ends_with(&format!("::{m};")));
        assert!(lib.contains(&format!("pub mod {m};")) || reexported, "lib.rs does not make {m} public");
    }
}

#[test]
fn storage_knows_no_geometry() {
    let storage = Path::new(env!("CARGO_MANIFEST_DIR")).join("storage");
    let manifest = std::fs::read_to_string(storage.join("Cargo.toml")).unwrap();
    for dep in ["hdov =", "hdov=", "glam", "wgpu", "obvhs", "meshopt"] {
        assert!(!manifest.contains(dep), "storage/Cargo.toml depends on {dep}");
    }
    let mut files = Vec::new();
    rust_files(&storage.join("src"), &mut files);
    for file in files {
        let code = code_of(&std::fs::read_to_string(&file).unwrap());
        assert!(!code.contains("hdov::"), "{} uses the library", file.display());
    }
}

#[test]
fn the_import_reader_reads_grouped_paths() {
    let code = code_of(
        "use crate::{db::{Database, access::Access}, error::Result};\n// crate::render in a comment\nlet s = \"crate::review\";\nuse crate::geom::Aabb;",
    );
    let found: Vec<String> = crate_paths(&code).into_iter().collect();
    assert_eq!(found, ["db", "error", "geom"]);
}

/// The module path of a file under a crate's `src/` (`dov/cpu/trace.rs` → `dov::cpu::trace`,
/// `dov/cpu/mod.rs` → `dov::cpu`, `lib.rs` and `main.rs` → the crate root).
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib" | "main")) {
        parts.pop();
    }
    parts
}

/// The paths that `code` (of module `module`) names, absolute from the crate root, as far as
/// their segments go: `crate::a::b`, `super::x` (the parent's child `x`), `self::y`, grouped
/// imports included (`super::{bvh::Hit, trace}` names `..::bvh::Hit` and `..::trace`).
fn absolute_paths(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let ident = |s: &str| -> String { s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect() };
    // The segments of `rest`, a path after its base: `a::b::{c, d::e}` → [a, b, c], [a, b, d, e].
    fn segments(rest: &str, ident: &dyn Fn(&str) -> String) -> Vec<Vec<String>> {
        let mut head = Vec::new();
        let mut s = rest.trim_start();
        loop {
            if let Some(group) = s.strip_prefix('{') {
                let mut out = Vec::new();
                let (mut depth, mut start) = (0, 0);
                for (i, c) in group.char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => {
                            out.push(&group[start..i]);
                            break;
                        }
                        '}' => depth -= 1,
                        ',' if depth == 0 => {
                            out.push(&group[start..i]);
                            start = i + 1;
                        }
                        _ => {}
                    }
                }
                return out
                    .into_iter()
                    .flat_map(|part| segments(part, ident))
                    .map(|tail| head.iter().cloned().chain(tail).collect())
                    .collect();
            }
            let name = ident(s);
            if name.is_empty() {
                return vec![head];
            }
            s = &s[name.len()..];
            head.push(name);
            match s.strip_prefix("::") {
                Some(next) => s = next,
                None => return vec![head],
            }
        }
    }
    let mut found = Vec::new();
    for base in ["crate::", "super::", "self::"] {
        for (at, _) in code.match_indices(base) {
            if code[..at].chars().last().is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue; // `hdov_crate::`, or the second `super::` of `super::super::`
            }
            let mut root: Vec<String> = match base {
                "crate::" => Vec::new(),
                "self::" => module.to_vec(),
                _ => module[..module.len().saturating_sub(1)].to_vec(),
            };
            let mut rest = &code[at + base.len()..];
            while let Some(r) = rest.strip_prefix("super::") {
                root.pop();
                rest = r;
            }
            for tail in segments(rest, &ident) {
                found.push(root.iter().cloned().chain(tail).collect());
            }
        }
    }
    found
}

/// Circles between the files of one folder (a *room*): for each module with children, its
/// children (files and subfolders) as nodes, and an edge where a file under one child names
/// another child by path. Names reached through a parent's re-export are not seen.
fn file_circles(src: &Path) -> Vec<String> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: Vec<(Vec<String>, String)> = files
        .iter()
        .map(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            // A file's own test module names the file as `super`: leave it out.
            let text = text.split("#[cfg(test)]").next().unwrap_or_default().to_string();
            (module_path(src, f), code_of(&text))
        })
        .collect();
    let all: BTreeSet<Vec<String>> = modules.iter().map(|m| m.0.clone()).collect();
    let mut circles = Vec::new();
    for room in all.iter().filter(|r| all.iter().any(|m| m.len() == r.len() + 1 && m.starts_with(r))) {
        let children: BTreeSet<&String> =
            all.iter().filter(|m| m.len() == room.len() + 1 && m.starts_with(room)).map(|m| &m[room.len()]).collect();
        let mut edges: BTreeSet<(String, String)> = BTreeSet::new();
        for (module, code) in modules.iter().filter(|(m, _)| m.len() > room.len() && m.starts_with(room)) {
            let from = &module[room.len()];
            for path in absolute_paths(code, module) {
                if path.len() > room.len() && path.starts_with(room) {
                    let to = &path[room.len()];
                    if to != from && children.contains(to) {
                        edges.insert((from.clone(), to.clone()));
                    }
                }
            }
        }
        // A circle is an edge whose target reaches its source.
        let reaches = |a: &String, b: &String| {
            let mut seen = BTreeSet::from([a.clone()]);
            let mut stack = vec![a.clone()];
            while let Some(n) = stack.pop() {
                if &n == b {
                    return true;
                }
                for (_, to) in edges.iter().filter(|(f, _)| *f == n) {
                    if seen.insert(to.clone()) {
                        stack.push(to.clone());
                    }
                }
            }
            false
        };
        for (from, to) in &edges {
            if reaches(to, from) {
                circles.push(format!(
                    "{}: {from} → {to} → … → {from}",
                    if room.is_empty() { "crate root".into() } else { room.join("::") }
                ));
            }
        }
    }
    circles
}

#[test]
fn no_circles_between_the_files_of_a_folder() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for src in ["src", "storage/src", "tools/src"] {
        let circles = file_circles(&root.join(src));
        assert!(circles.is_empty(), "{src}: files that import each other:\n{}", circles.join("\n"));
    }
}

#[test]
fn the_circle_finder_finds_circles() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    };
    write("lib.rs", "mod room;");
    write("room/mod.rs", "mod a; mod b; mod c; pub use a::A;");
    write("room/a.rs", "use super::{b::B, c};");
    write("room/b.rs", "use crate::room::c::C;\n#[cfg(test)]\nmod tests { use super::super::a::A; }");
    write("room/c.rs", "fn f() { super::super::room::a::g() }");
    let circles = file_circles(dir.path());
    assert_eq!(circles, ["room: a → b → … → a", "room: a → c → … → a", "room: b → c → … → b", "room: c → a → … → c"]);
    write("room/c.rs", "use super::A; // through the re-export: not seen");
    assert!(file_circles(dir.path()).is_empty());
}
