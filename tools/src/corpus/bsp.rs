//! Quake III Arena / OpenArena levels (IBSP version 46), read for the corpus: the triangles the
//! game draws, grouped as the file groups them (one object per shader, spanning the level, as
//! an exporter writes them), the places where players stand (spawn points and pick-ups), and
//! the level's own potentially visible set (the compiler's cluster-to-cluster bit vectors).
//!
//! Coordinates become hdov's: y up (Quake's z), in metres at [`METRES_PER_UNIT`]. Bézier
//! patches are tessellated at [`PATCH_STEPS`] steps per side of each 3 × 3 piece, both for the
//! scene and for counting the faces of the PVS, so that the two counts are of one geometry;
//! then every edge that another triangle's vertex lies on is split there
//! ([`Level::close_t_junctions`]), so that no hairline crack shows what lies behind a wall.

use std::collections::HashMap;

use glam::{Vec3, Vec3A};

/// Quake units per metre: a player is 56 units tall (1.75 m) with eyes 50 units above the floor
/// (1.56 m).
pub const METRES_PER_UNIT: f32 = 1.0 / 32.0;
/// A player's eyes above the floor, in Quake units (26 above the origin, which is 24 above the
/// feet).
pub const EYE_UNITS: f32 = 50.0;
/// Steps per side of each 3 × 3 piece of a Bézier patch.
pub const PATCH_STEPS: usize = 2;

/// A level as hdov reads it, with what the game knows about it.
pub struct Level {
    /// Triangles in hdov's coordinates (metres, y up), counter-clockwise seen from the front.
    pub triangles: Vec<[Vec3; 3]>,
    /// The BSP face each triangle comes from.
    pub face_of: Vec<u32>,
    /// The shader (texture) each BSP face is drawn with, by face.
    pub shader_of_face: Vec<u32>,
    /// The shaders' names.
    pub shaders: Vec<String>,
    /// Where players stand: spawn points and pick-ups, (class name, origin in hdov's
    /// coordinates) as the entities lump places them (not yet dropped to the floor).
    pub places: Vec<(String, Vec3)>,
    planes: Vec<(Vec3, f32)>,
    nodes: Vec<(i32, [i32; 2])>,
    /// (cluster, first leaf face, leaf faces).
    leafs: Vec<(i32, usize, usize)>,
    leaf_faces: Vec<u32>,
    /// (clusters, bytes per cluster, bits).
    vis: Option<(usize, usize, Vec<u8>)>,
}

/// `(x, y, z)` of Quake (z up) in hdov's frame (y up), in metres: a rotation about x, so the
/// winding of a triangle is kept.
pub fn to_hdov(q: Vec3) -> Vec3 {
    Vec3::new(q.x, q.z, -q.y) * METRES_PER_UNIT
}

fn to_quake(p: Vec3) -> Vec3 {
    Vec3::new(p.x, -p.z, p.y) / METRES_PER_UNIT
}

struct Reader<'a> {
    bytes: &'a [u8],
    lumps: [(usize, usize); 17],
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8]) -> Result<Reader<'a>, String> {
        if bytes.len() < 8 + 17 * 8 || &bytes[..4] != b"IBSP" {
            return Err("not a Quake III BSP (no IBSP header)".into());
        }
        let version = i32::from_le_bytes(bytes[4..8].try_into().unwrap());
        if version != 46 {
            return Err(format!("BSP version {version}; Quake III Arena's is 46"));
        }
        let mut lumps = [(0, 0); 17];
        for (k, lump) in lumps.iter_mut().enumerate() {
            let at = 8 + k * 8;
            let offset = i32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
            let len = i32::from_le_bytes(bytes[at + 4..at + 8].try_into().unwrap());
            let (offset, len) = (
                usize::try_from(offset).map_err(|_| "negative lump offset")?,
                usize::try_from(len).map_err(|_| "negative lump length")?,
            );
            if offset.checked_add(len).is_none_or(|end| end > bytes.len()) {
                return Err(format!("lump {k} runs past the end of the file"));
            }
            *lump = (offset, len);
        }
        Ok(Reader { bytes, lumps })
    }

    /// Lump `k` as records of `size` bytes.
    fn records(&self, k: usize, size: usize) -> Result<impl Iterator<Item = &'a [u8]>, String> {
        let (offset, len) = self.lumps[k];
        if len % size != 0 {
            return Err(format!("lump {k} is {len} bytes, not a whole number of {size}-byte records"));
        }
        Ok(self.bytes[offset..offset + len].chunks_exact(size))
    }

    fn lump(&self, k: usize) -> &'a [u8] {
        let (offset, len) = self.lumps[k];
        &self.bytes[offset..offset + len]
    }
}

fn i32_at(b: &[u8], k: usize) -> i32 {
    i32::from_le_bytes(b[4 * k..4 * k + 4].try_into().unwrap())
}

fn f32_at(b: &[u8], k: usize) -> f32 {
    f32::from_le_bytes(b[4 * k..4 * k + 4].try_into().unwrap())
}

fn vec_at(b: &[u8], k: usize) -> Vec3 {
    Vec3::new(f32_at(b, k), f32_at(b, k + 1), f32_at(b, k + 2))
}

fn index(i: i32, len: usize, what: &str) -> Result<usize, String> {
    usize::try_from(i).ok().filter(|&i| i < len).ok_or_else(|| format!("{what} index {i} is out of range (0..{len})"))
}

impl Level {
    /// Reads a level from the bytes of its `.bsp`.
    pub fn parse(bytes: &[u8]) -> Result<Level, String> {
        let r = Reader::new(bytes)?;
        let shaders: Vec<String> =
            // A C string in 64 bytes: what follows its first NUL is whatever the compiler left.
            r.records(1, 72)?.map(|t| String::from_utf8_lossy(t[..64].split(|&b| b == 0).next().unwrap_or(&[])).into_owned()).collect();
        let planes: Vec<(Vec3, f32)> = r.records(2, 16)?.map(|p| (vec_at(p, 0), f32_at(p, 3))).collect();
        let nodes: Vec<(i32, [i32; 2])> =
            r.records(3, 36)?.map(|n| (i32_at(n, 0), [i32_at(n, 1), i32_at(n, 2)])).collect();
        let leafs: Vec<(i32, usize, usize)> = r
            .records(4, 48)?
            .map(|l| (i32_at(l, 0), i32_at(l, 8).max(0) as usize, i32_at(l, 9).max(0) as usize))
            .collect();
        let leaf_faces: Vec<u32> = r.records(5, 4)?.map(|f| i32_at(f, 0).max(0) as u32).collect();
        let vertices: Vec<(Vec3, Vec3)> = r.records(10, 44)?.map(|v| (vec_at(v, 0), vec_at(v, 7))).collect();
        let mesh_verts: Vec<i32> = r.records(11, 4)?.map(|m| i32_at(m, 0)).collect();
        let vis = {
            let v = r.lump(16);
            if v.len() >= 8 {
                let (n, size) = (i32_at(v, 0).max(0) as usize, i32_at(v, 1).max(0) as usize);
                let bits = v[8..].to_vec();
                (n.checked_mul(size).is_some_and(|b| b <= bits.len()) && n > 0).then_some((n, size, bits))
            } else {
                None
            }
        };
        let mut level = Level {
            triangles: Vec::new(),
            face_of: Vec::new(),
            shader_of_face: Vec::new(),
            shaders,
            places: places(&String::from_utf8_lossy(r.lump(0))),
            planes,
            nodes,
            leafs,
            leaf_faces,
            vis,
        };
        for (face, f) in r.records(13, 104)?.enumerate() {
            let shader = index(i32_at(f, 0), level.shaders.len(), "shader")?;
            level.shader_of_face.push(shader as u32);
            let (kind, first, count) = (i32_at(f, 2), i32_at(f, 3), i32_at(f, 4).max(0) as usize);
            let first_vertex = index(first, vertices.len() + 1, "vertex")?;
            let verts =
                vertices.get(first_vertex..first_vertex + count).ok_or("a face's vertices run past the lump")?;
            let triangles: Vec<[(Vec3, Vec3); 3]> = match kind {
                // Polygons and meshes: triangles by the mesh vertex lump.
                1 | 3 => {
                    let (m, n) = (i32_at(f, 5), i32_at(f, 6).max(0) as usize);
                    let m = index(m, mesh_verts.len() + 1, "mesh vertex")?;
                    let offsets = mesh_verts.get(m..m + n).ok_or("a face's mesh vertices run past the lump")?;
                    offsets
                        .chunks_exact(3)
                        .map(|t| {
                            let v = |k: usize| {
                                verts.get(t[k].max(0) as usize).copied().ok_or("a mesh vertex past its face")
                            };
                            Ok([v(0)?, v(1)?, v(2)?])
                        })
                        .collect::<Result<_, String>>()?
                }
                2 => patch(verts, [i32_at(f, 24).max(0) as usize, i32_at(f, 25).max(0) as usize])?,
                // Billboards (flares) have no surface.
                _ => Vec::new(),
            };
            for t in triangles {
                let p = t.map(|v| to_hdov(v.0));
                let normal = to_hdov(t[0].1 + t[1].1 + t[2].1);
                let n = (p[1] - p[0]).cross(p[2] - p[0]);
                if n.length_squared() == 0.0 {
                    continue;
                }
                // Wound so that counter-clockwise faces the side the game lights (its normals).
                level.triangles.push(if n.dot(normal) < 0.0 { [p[0], p[2], p[1]] } else { p });
                level.face_of.push(face as u32);
            }
        }
        level.close_t_junctions();
        Ok(level)
    }

    /// Splits every triangle edge that another triangle's vertex lies on (within
    /// [`T_JUNCTION_TOLERANCE`]). The game's compiler closes the T-junctions of its brush faces,
    /// but a curved patch tessellated here meets the faces around it at vertices they lack, and
    /// the hairline crack along such an edge shows what lies behind a wall as a line of single
    /// texels. A triangle takes at most [`T_JUNCTION_SPLITS`] splits (else it stays whole), and
    /// a sliver narrower than the tolerance is not split (every vertex near it is near each of
    /// its edges).
    fn close_t_junctions(&mut self) {
        let tol = T_JUNCTION_TOLERANCE;
        let cell = 0.5f32;
        let key = |p: Vec3| (p / cell).floor().as_ivec3();
        let mut hash: HashMap<glam::IVec3, Vec<Vec3>> = HashMap::new();
        for t in &self.triangles {
            for &v in t {
                let bucket = hash.entry(key(v)).or_default();
                if !bucket.iter().any(|&q| q.distance_squared(v) <= tol * tol) {
                    bucket.push(v);
                }
            }
        }
        // The vertex nearest `a` strictly inside edge a–b and apart from `corners`, if any.
        let on_edge = |a: Vec3, b: Vec3, corners: &[Vec3; 3]| -> Option<Vec3> {
            let d = b - a;
            let len2 = d.length_squared();
            let steps = (len2.sqrt() / (0.5 * cell)).ceil() as i32;
            let mut keys: Vec<glam::IVec3> = (0..=steps)
                .flat_map(|k| {
                    let c = key(a + d * (k as f32 / steps.max(1) as f32));
                    (0..27).map(move |n| c + glam::IVec3::new(n % 3 - 1, n / 3 % 3 - 1, n / 9 - 1))
                })
                .collect();
            keys.sort_unstable_by_key(|k| (k.x, k.y, k.z));
            keys.dedup();
            keys.iter()
                .flat_map(|k| hash.get(k))
                .flatten()
                .filter(|&&v| corners.iter().all(|&c| c.distance_squared(v) > tol * tol))
                .map(|&v| ((v - a).dot(d) / len2, v))
                .filter(|&(s, v)| s > 0.0 && s < 1.0 && (a + d * s).distance_squared(v) <= tol * tol)
                .min_by(|p, q| p.0.total_cmp(&q.0))
                .map(|(_, v)| v)
        };
        let triangles = std::mem::take(&mut self.triangles);
        let faces = std::mem::take(&mut self.face_of);
        for (whole, face) in triangles.into_iter().zip(faces) {
            let (mut todo, mut done, mut splits) = (vec![whole], Vec::new(), 0);
            while let Some(t) = todo.pop() {
                let longest = (0..3).map(|e| t[e].distance(t[(e + 1) % 3])).fold(0.0, f32::max);
                let sliver = (t[1] - t[0]).cross(t[2] - t[0]).length() <= tol * longest;
                let split =
                    if sliver { None } else { (0..3).find_map(|e| on_edge(t[e], t[(e + 1) % 3], &t).map(|v| (e, v))) };
                match split {
                    Some((e, v)) => {
                        let (a, b, c) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
                        todo.extend([[v, b, c], [a, v, c]]);
                        splits += 1;
                        if splits > T_JUNCTION_SPLITS {
                            (todo, done) = (Vec::new(), vec![whole]);
                        }
                    }
                    None => done.push(t),
                }
            }
            self.face_of.extend(std::iter::repeat_n(face, done.len()));
            self.triangles.extend(done);
        }
    }

    /// The cluster of the leaf holding `p` (hdov's coordinates), `None` in solid or outside.
    pub fn cluster_at(&self, p: Vec3) -> Option<usize> {
        let q = to_quake(p);
        let mut node = 0i32;
        let mut steps = 0;
        while node >= 0 {
            let (plane, children) = *self.nodes.get(node as usize)?;
            let (normal, dist) = *self.planes.get(usize::try_from(plane).ok()?)?;
            node = if normal.dot(q) - dist >= 0.0 { children[0] } else { children[1] };
            steps += 1;
            if steps > self.nodes.len() {
                return None;
            }
        }
        let leaf = self.leafs.get((-(node + 1)) as usize)?;
        usize::try_from(leaf.0).ok()
    }

    /// The triangles of the faces the game draws from `cluster`: those of every leaf in a
    /// cluster its PVS holds (all of them without visibility data).
    pub fn pvs_triangles(&self, cluster: usize) -> usize {
        let visible = |other: i32| match (&self.vis, usize::try_from(other)) {
            (_, Err(_)) => false,
            (None, _) => true,
            (Some((n, size, bits)), Ok(o)) => {
                cluster < *n && o < *n && bits[cluster * size + o / 8] & (1 << (o % 8)) != 0
            }
        };
        let mut faces = vec![false; self.shader_of_face.len()];
        for &(c, first, count) in &self.leafs {
            if visible(c) {
                for &f in self.leaf_faces.iter().skip(first).take(count) {
                    if let Some(seen) = faces.get_mut(f as usize) {
                        *seen = true;
                    }
                }
            }
        }
        self.face_of.iter().filter(|&&f| faces[f as usize]).count()
    }

    /// The triangles grouped by shader, in shader order: one object per shader, as the file
    /// groups them.
    pub fn by_shader(&self) -> Vec<(String, Vec<[Vec3; 3]>)> {
        let mut groups: HashMap<u32, Vec<[Vec3; 3]>> = HashMap::new();
        for (t, &face) in self.triangles.iter().zip(&self.face_of) {
            groups.entry(self.shader_of_face[face as usize]).or_default().push(*t);
        }
        let mut out: Vec<(u32, Vec<[Vec3; 3]>)> = groups.into_iter().collect();
        out.sort_by_key(|g| g.0);
        out.into_iter().map(|(s, t)| (self.shaders[s as usize].clone(), t)).collect()
    }
}

/// How near an edge (metres) a vertex counts as on it ([`Level::close_t_junctions`]): 1/16 of a
/// Quake unit.
const T_JUNCTION_TOLERANCE: f32 = METRES_PER_UNIT / 16.0;

/// Most splits one triangle takes closing T-junctions.
const T_JUNCTION_SPLITS: usize = 64;

/// A patch's triangles: each 3 × 3 piece of its `size` control points as a biquadratic Bézier
/// surface, [`PATCH_STEPS`] steps a side.
fn patch(verts: &[(Vec3, Vec3)], size: [usize; 2]) -> Result<Vec<[(Vec3, Vec3); 3]>, String> {
    let [w, h] = size;
    if w < 3 || h < 3 || w % 2 == 0 || h % 2 == 0 || w * h > verts.len() {
        return Err(format!("a patch of {w} × {h} control points"));
    }
    let bez = |a: Vec3A, b: Vec3A, c: Vec3A, t: f32| a * (1.0 - t) * (1.0 - t) + b * 2.0 * t * (1.0 - t) + c * t * t;
    let mut out = Vec::new();
    let n = PATCH_STEPS;
    for py in (0..h - 1).step_by(2) {
        for px in (0..w - 1).step_by(2) {
            let cp = |i: usize, j: usize| verts[(py + j) * w + px + i];
            let point = |s: f32, t: f32, pick: fn(&(Vec3, Vec3)) -> Vec3| {
                let row = |j| bez(pick(&cp(0, j)).into(), pick(&cp(1, j)).into(), pick(&cp(2, j)).into(), s);
                Vec3::from(bez(row(0), row(1), row(2), t))
            };
            let grid: Vec<(Vec3, Vec3)> = (0..=n)
                .flat_map(|j| (0..=n).map(move |i| (i as f32 / n as f32, j as f32 / n as f32)))
                .map(|(s, t)| (point(s, t, |v| v.0), point(s, t, |v| v.1)))
                .collect();
            for j in 0..n {
                for i in 0..n {
                    let k = j * (n + 1) + i;
                    let (a, b, c, d) = (grid[k], grid[k + 1], grid[k + n + 1], grid[k + n + 2]);
                    out.push([a, b, d]);
                    out.push([a, d, c]);
                }
            }
        }
    }
    Ok(out)
}

/// The origins of the entities a player stands at: spawn points and pick-ups.
fn places(entities: &str) -> Vec<(String, Vec3)> {
    let mut out = Vec::new();
    for block in entities.split('}') {
        let mut class = None;
        let mut origin = None;
        for line in block.lines() {
            let parts: Vec<&str> = line.split('"').collect();
            if parts.len() >= 4 {
                match parts[1] {
                    "classname" => class = Some(parts[3].to_string()),
                    "origin" => {
                        let v: Vec<f32> = parts[3].split_whitespace().filter_map(|x| x.parse().ok()).collect();
                        if v.len() == 3 {
                            origin = Some(Vec3::new(v[0], v[1], v[2]));
                        }
                    }
                    _ => {}
                }
            }
        }
        if let (Some(class), Some(origin)) = (class, origin) {
            let standing = ["info_player", "team_CTF_", "weapon_", "item_", "ammo_", "holdable_"];
            if standing.iter().any(|s| class.starts_with(s)) {
                out.push((class, to_hdov(origin)));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_keep_handedness() {
        let q = Vec3::new(32.0, 64.0, 96.0);
        assert!((to_quake(to_hdov(q)) - q).length() < 1e-4);
        assert_eq!(to_hdov(Vec3::Z), Vec3::Y * METRES_PER_UNIT);
        let (x, y) = (to_hdov(Vec3::X), to_hdov(Vec3::Y));
        assert!((x.cross(y) - to_hdov(Vec3::Z) * METRES_PER_UNIT).length() < 1e-9);
    }

    #[test]
    fn entities_give_the_places_players_stand() {
        let text = "{\n\"classname\" \"worldspawn\"\n}\n{\n\"origin\" \"0 0 24\"\n\"classname\" \"info_player_deathmatch\"\n}\n{\n\"classname\" \"light\"\n\"origin\" \"1 2 3\"\n}\n{\n\"classname\" \"weapon_shotgun\"\n\"origin\" \"32 0 8\"\n}";
        let p = places(text);
        assert_eq!(p.len(), 2);
        assert_eq!(p[0], ("info_player_deathmatch".to_string(), to_hdov(Vec3::new(0.0, 0.0, 24.0))));
    }

    #[test]
    fn a_flat_patch_tessellates_onto_its_plane() {
        let verts: Vec<(Vec3, Vec3)> =
            (0..9).map(|k| (Vec3::new((k % 3) as f32, (k / 3) as f32, 0.0), Vec3::Z)).collect();
        let t = patch(&verts, [3, 3]).unwrap();
        assert_eq!(t.len(), 2 * PATCH_STEPS * PATCH_STEPS);
        assert!(t.iter().flatten().all(|v| v.0.z == 0.0 && v.0.x <= 2.0 && v.0.y <= 2.0));
        assert!(patch(&verts, [2, 3]).is_err());
    }

    /// A triangle whose edge runs past a vertex of the two triangles beside it is split there,
    /// keeping its face, its winding and its area; the others stay as they are.
    #[test]
    fn t_junctions_are_closed() {
        let v = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        let big = [v(0.0, 0.0), v(2.0, 0.0), v(0.0, 2.0)];
        let small = [[v(0.0, 0.0), v(1.0, -1.0), v(1.0, 0.0)], [v(1.0, 0.0), v(1.0, -1.0), v(2.0, 0.0)]];
        let mut level = Level {
            triangles: vec![big, small[0], small[1]],
            face_of: vec![7, 8, 8],
            shader_of_face: Vec::new(),
            shaders: Vec::new(),
            places: Vec::new(),
            planes: Vec::new(),
            nodes: Vec::new(),
            leafs: Vec::new(),
            leaf_faces: Vec::new(),
            vis: None,
        };
        level.close_t_junctions();
        let area = |t: &[Vec3; 3]| (t[1] - t[0]).cross(t[2] - t[0]);
        let of_big: Vec<&[Vec3; 3]> =
            level.triangles.iter().zip(&level.face_of).filter(|p| *p.1 == 7).map(|p| p.0).collect();
        assert_eq!(of_big.len(), 2);
        assert!(of_big.iter().all(|t| t.contains(&v(1.0, 0.0)) && area(t).z > 0.0));
        assert!((of_big.iter().map(|t| area(t).z).sum::<f32>() - area(&big).z).abs() < 1e-6);
        assert_eq!(level.triangles.len(), 4);
    }

    /// A shader's name is a C string in its 64 bytes: compilers leave junk after the NUL.
    #[test]
    fn shader_names_end_at_their_nul() {
        let mut bsp = b"IBSP".to_vec();
        bsp.extend(46i32.to_le_bytes());
        let start: i32 = 8 + 17 * 8;
        for lump in 0..17 {
            let len: i32 = if lump == 1 { 72 } else { 0 };
            bsp.extend(start.to_le_bytes());
            bsp.extend(len.to_le_bytes());
        }
        let mut shader = b"textures/base/floor\0\0junk\x01p\0q".to_vec();
        shader.resize(72, 0);
        bsp.extend(shader);
        assert_eq!(Level::parse(&bsp).unwrap().shaders, vec!["textures/base/floor".to_string()]);
    }

    #[test]
    fn junk_is_refused() {
        assert!(Level::parse(b"not a level").is_err_and(|e| e.contains("IBSP")));
        let mut header = b"IBSP".to_vec();
        header.extend(45i32.to_le_bytes());
        header.resize(8 + 17 * 8, 0);
        assert!(Level::parse(&header).err().is_some_and(|e| e.contains("version 45")));
    }
}
