//! A 3D Tiles tileset as a client sees it: `tileset.json` with the subtree tilesets it names
//! (external tilesets, `hdov export --3dtiles`'s `subtrees/`) put in place.

use serde_json::Value;

/// The tileset `set` (`tileset.json` read) with every tile whose content is another tileset
/// given that tileset's root as its only child (the tile's content left out), and every content
/// URI made relative to the tileset's own folder. `load` reads a file by that relative path.
pub fn resolved(set: &Value, load: &mut dyn FnMut(&str) -> Value) -> Value {
    let mut out = set.clone();
    resolve_tile(&mut out["root"], "", load);
    out
}

fn resolve_tile(tile: &mut Value, base: &str, load: &mut dyn FnMut(&str) -> Value) {
    if let Some(uri) = tile["content"]["uri"].as_str() {
        let path = relative(base, uri);
        if path.ends_with(".json") {
            let mut sub = load(&path)["root"].clone();
            let folder = path.rfind('/').map_or("", |i| &path[..=i]).to_string();
            resolve_tile(&mut sub, &folder, load);
            tile.as_object_mut().expect("a tile is an object").remove("content");
            tile["children"] = Value::Array(vec![sub]);
            return;
        }
        tile["content"]["uri"] = Value::String(path);
    }
    for c in tile.get_mut("children").and_then(Value::as_array_mut).into_iter().flatten() {
        resolve_tile(c, base, load);
    }
}

/// `uri` (relative to the folder `base`, which ends in `/` or is empty) relative to the
/// tileset's folder: `..` and `.` resolved.
fn relative(base: &str, uri: &str) -> String {
    let mut parts: Vec<&str> = base.split('/').filter(|p| !p.is_empty()).collect();
    for p in uri.split('/') {
        match p {
            "." | "" => {}
            ".." => {
                parts.pop().expect("a URI inside the tileset's folder");
            }
            p => parts.push(p),
        }
    }
    parts.join("/")
}

#[cfg(test)]
mod tests {
    #[test]
    fn uris_are_resolved_against_their_tilesets_folder() {
        assert_eq!(super::relative("", "content/a.glb"), "content/a.glb");
        assert_eq!(super::relative("subtrees/", "../content/a.glb"), "content/a.glb");
        assert_eq!(super::relative("subtrees/", "../subtrees/n2.json"), "subtrees/n2.json");
        assert_eq!(super::relative("a/b/", "./c.glb"), "a/b/c.glb");
    }
}
