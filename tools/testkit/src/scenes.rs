//! Scenes built in code for the DoV tests: tessellated spheres, boxes, walls with holes.

use glam::{Mat4, Vec3};
use hdov::geom::Aabb;
use hdov::grid::ViewGrid;
use hdov::scene::{BaseMesh, Mesh, Object, Scene};

/// An icosphere of radius 1 around the origin, `subdivisions` times refined (20·4^s triangles),
/// counter-clockwise seen from outside.
pub fn icosphere(subdivisions: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| Vec3::from(*p).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints = std::collections::HashMap::new();
        let mut mid = |a: u32, b: u32, positions: &mut Vec<Vec3>| -> u32 {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                positions.push(((positions[a as usize] + positions[b as usize]) * 0.5).normalize());
                positions.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = mid(a, b, &mut positions);
            let bc = mid(b, c, &mut positions);
            let ca = mid(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    let mesh = Mesh {
        positions: positions.iter().map(|p| p.to_array()).collect(),
        indices: faces.into_iter().flatten().collect(),
    };
    assert_outward(&mesh);
    mesh
}

fn assert_outward(mesh: &Mesh) {
    for [a, b, c] in mesh.triangles() {
        let n = (b - a).cross(c - a);
        assert!(n.dot(a + b + c) > 0.0, "test mesh triangle is not counter-clockwise from outside");
    }
}

/// The library's unit cube, checked to face outwards.
pub fn unit_cube() -> Mesh {
    let mesh = Mesh::unit_cube();
    assert_outward(&mesh);
    mesh
}

/// A scene builder: each added object gets the next index.
#[derive(Default)]
pub struct SceneBuilder {
    pub scene: Scene,
}

impl SceneBuilder {
    pub fn mesh(&mut self, name: &str, mesh: Mesh) -> u32 {
        self.scene.meshes.push(BaseMesh { name: name.into(), mesh });
        self.scene.meshes.len() as u32 - 1
    }

    pub fn object(&mut self, mesh: u32, transform: Mat4) -> u32 {
        let id = self.scene.objects.len();
        self.scene.objects.push(Object { name: format!("o{id}"), mesh, transform, part: None });
        id as u32
    }

    /// An axis-aligned box object with the given corners.
    pub fn aabox(&mut self, min: Vec3, max: Vec3) -> u32 {
        let id = self.scene.objects.len();
        self.scene.add_box(&format!("o{id}"), min, max)
    }

    pub fn build(self) -> Scene {
        self.scene.check().expect("test scene is valid");
        self.scene
    }
}

/// A sphere scene: one icosphere of radius `r` at `centre`.
pub fn sphere_scene(subdivisions: u32, centre: Vec3, r: f32) -> Scene {
    let mut b = SceneBuilder::default();
    let m = b.mesh("sphere", icosphere(subdivisions));
    b.object(m, Mat4::from_scale_rotation_translation(Vec3::splat(r), glam::Quat::IDENTITY, centre));
    b.build()
}

/// The analytic DoV of a sphere of radius r at distance d: (1 − √(1 − (r/d)²)) / 2.
pub fn sphere_dov(r: f64, d: f64) -> f64 {
    (1.0 - (1.0 - (r / d).powi(2)).sqrt()) / 2.0
}

/// A deterministic pseudo-random generator (SplitMix64) for scene layouts.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }
}

/// Boxes scattered around the origin in every direction (none near the origin), sizes and
/// distances varied so that they overlap in view: occlusion between objects is exercised. With
/// `rotated`, each box gets a random orientation, so that no edge runs parallel to a texel row.
pub fn box_field(count: usize, seed: u64, rotated: bool) -> Scene {
    let mut rng = Rng(seed);
    let mut b = SceneBuilder::default();
    let cube = b.mesh("cube", unit_cube());
    while b.scene.objects.len() < count {
        let c = Vec3::new(rng.range(-20.0, 20.0), rng.range(-20.0, 20.0), rng.range(-20.0, 20.0));
        let size = Vec3::new(rng.range(0.6, 6.0), rng.range(0.6, 6.0), rng.range(0.6, 6.0));
        let axis = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let angle = rng.range(0.0, std::f32::consts::TAU);
        // Keep the origin (the viewpoint) well outside every box, whatever its orientation.
        if c.length() < size.length() * 0.5 + 1.0 || axis.length() < 0.1 {
            continue;
        }
        let rotation =
            if rotated { glam::Quat::from_axis_angle(axis.normalize(), angle) } else { glam::Quat::IDENTITY };
        b.object(cube, Mat4::from_scale_rotation_translation(size, rotation, c));
    }
    b.build()
}

/// Whether GPU tests should run here (prints `skipped: no adapter` otherwise).
pub fn gpu_or_skip() -> bool {
    crate::gpu::adapter_or_skip()
}

/// A block of `n × n` buildings (boxes 14 × 14, heights 10..70, on a 20 pitch: streets 6 wide)
/// on a ground slab (object 0). With `props`, the streets also get poles (0.3 × 4 × 0.3) and low
/// walls (6 × 1.2 × 0.2) — the small objects that corner sampling tends to miss.
pub fn city_block(n: u32, props: bool) -> Scene {
    let mut b = SceneBuilder::default();
    let extent = n as f32 * 20.0;
    b.aabox(Vec3::new(-10.0, -1.0, -10.0), Vec3::new(extent + 10.0, 0.0, extent + 10.0));
    for i in 0..n {
        for j in 0..n {
            let h = 10.0 + ((i * 7 + j * 13) % 13) as f32 * 5.0;
            let (x, z) = (i as f32 * 20.0, j as f32 * 20.0);
            b.aabox(Vec3::new(x, 0.0, z), Vec3::new(x + 14.0, h, z + 14.0));
        }
    }
    if props {
        let mut rng = Rng(99);
        for i in 0..n {
            for j in 0..n {
                let (x, z) = (i as f32 * 20.0, j as f32 * 20.0);
                // Poles along the street east of the building, walls along the one south of it.
                let pz = z + rng.range(1.0, 13.0);
                let px = x + 14.0 + rng.range(0.5, 5.2);
                b.aabox(Vec3::new(px, 0.0, pz), Vec3::new(px + 0.3, 4.0, pz + 0.3));
                let wx = x + rng.range(0.0, 8.0);
                let wz = z + 14.0 + rng.range(0.5, 5.5);
                b.aabox(Vec3::new(wx, 0.0, wz), Vec3::new(wx + 6.0, 1.2, wz + 0.2));
            }
        }
    }
    b.build()
}

/// A small town: `n × n` boxes of varied height, each its own base mesh, and a sphere instanced
/// on every other street corner (so instancing is exercised), an icosphere of
/// `ball_subdivisions`.
pub fn town(n: usize, ball_subdivisions: u32) -> Scene {
    let mut scene = Scene::default();
    scene.meshes.push(BaseMesh { name: "ball".into(), mesh: icosphere(ball_subdivisions) });
    for i in 0..n {
        for j in 0..n {
            let (x, z) = (i as f32 * 20.0, j as f32 * 20.0);
            let h = 5.0 + ((i * 7 + j * 13) % 11) as f32 * 3.0;
            let name = format!("house_{i}_{j}");
            let place = Mat4::from_translation(Vec3::new(x + 6.0, h / 2.0, z + 6.0))
                * Mat4::from_scale(Vec3::new(12.0, h, 12.0));
            scene.objects.push(Object {
                name: name.clone(),
                mesh: scene.meshes.len() as u32,
                transform: Mat4::IDENTITY,
                part: None,
            });
            scene.meshes.push(BaseMesh { name, mesh: unit_cube().transformed(&place) });
            if (i + j) % 2 == 0 {
                let transform = Mat4::from_translation(Vec3::new(x + 16.0, 1.0, z + 16.0));
                scene.objects.push(Object { name: format!("ball_{i}_{j}"), mesh: 0, transform, part: None });
            }
        }
    }
    scene
}

/// A street as issue 22 describes it, with its grid: a row of houses on each side with 1 m gaps
/// between them, yards behind with sheds, then a second row of houses; poles along the kerbs; a
/// slatted fence (0.1 m slats, 0.15 m gaps) in front of a yard on the south side. The grid is
/// 18 cells of 5 × 0.5 × 2 m along the street's middle at eye height: from part of a cell a
/// house in the second row shows through a gap, from the rest it does not.
pub fn street_with_gaps() -> (Scene, ViewGrid) {
    let mut b = SceneBuilder::default();
    let mut rng = Rng(22);
    b.aabox(Vec3::new(-20.0, -1.0, -45.0), Vec3::new(110.0, 0.0, 50.0));
    let row = |b: &mut SceneBuilder, rng: &mut Rng, z0: f32, z1: f32, x0: f32| {
        let mut x = x0;
        while x < 95.0 {
            let w = rng.range(6.0, 10.0);
            b.aabox(Vec3::new(x, 0.0, z0), Vec3::new(x + w, rng.range(6.0, 15.0), z1));
            x += w + 1.0;
        }
    };
    // North: the first row, yards with sheds, the second row (offset, so gaps do not line up).
    row(&mut b, &mut rng, 9.0, 19.0, -5.0);
    for _ in 0..24 {
        let (x, z, w) = (rng.range(-5.0, 95.0), rng.range(20.0, 30.0), rng.range(0.8, 2.5));
        b.aabox(Vec3::new(x, 0.0, z), Vec3::new(x + w, rng.range(1.0, 2.5), z + w));
    }
    row(&mut b, &mut rng, 32.0, 42.0, -1.5);
    // South: houses, except a yard behind a slatted fence from x = 30 to 55.
    for (x0, x1) in [(-5.0f32, 30.0f32), (55.0, 95.0)] {
        let mut x = x0;
        while x < x1 {
            let w = rng.range(6.0, 9.0).min(x1 - x);
            b.aabox(Vec3::new(x, 0.0, -14.0), Vec3::new(x + w, rng.range(6.0, 15.0), -4.0));
            x += w + 1.0;
        }
    }
    let mut x = 30.0;
    while x < 55.0 {
        b.aabox(Vec3::new(x, 0.0, -1.05), Vec3::new(x + 0.1, 1.8, -1.0));
        x += 0.25;
    }
    for _ in 0..12 {
        let (x, z, w) = (rng.range(30.0, 54.0), rng.range(-12.0, -3.0), rng.range(0.5, 2.0));
        b.aabox(Vec3::new(x, 0.0, z), Vec3::new(x + w, rng.range(0.8, 3.0), z + w));
    }
    b.aabox(Vec3::new(28.0, 0.0, -30.0), Vec3::new(57.0, 9.0, -20.0));
    // Poles along both kerbs.
    for k in 0..10 {
        for z in [-0.5f32, 8.0] {
            let x = k as f32 * 9.5 + rng.range(0.0, 3.0);
            b.aabox(Vec3::new(x, 0.0, z), Vec3::new(x + 0.2, 5.0, z + 0.2));
        }
    }
    let grid = ViewGrid::new(Aabb::new(Vec3::new(0.0, 1.5, 3.0), Vec3::new(90.0, 2.0, 5.0)), [18, 1, 1]);
    (b.build(), grid)
}

/// A two-storey building, 10 × 10 m, as a BIM export has it: one object per slab, per wall and
/// per storey's partition, no grid of its own. Ground slab at y = 0, upper floor at 3.3, roof at
/// 6.3–6.6; 0.3 m outer walls; on the ground floor a partition at x = 5 with a door (z 4–5, 2.2 m
/// high) and a solid core, x and z from 6 to 9.7, 3 m high (a lift shaft's concrete, say), whose
/// middle no one can stand in. Viewers' eyes are at 1–2 m above either floor (or on the roof).
pub fn two_storey_building() -> Scene {
    let mut b = SceneBuilder::default();
    let v = Vec3::new;
    b.aabox(v(0.0, -0.3, 0.0), v(10.0, 0.0, 10.0));
    b.aabox(v(0.0, 3.0, 0.0), v(10.0, 3.3, 10.0));
    b.aabox(v(0.0, 6.3, 0.0), v(10.0, 6.6, 10.0));
    for (y0, y1) in [(0.0, 3.0), (3.3, 6.3)] {
        b.aabox(v(0.0, y0, 0.0), v(0.3, y1, 10.0));
        b.aabox(v(9.7, y0, 0.0), v(10.0, y1, 10.0));
        b.aabox(v(0.3, y0, 0.0), v(9.7, y1, 0.3));
        b.aabox(v(0.3, y0, 9.7), v(9.7, y1, 10.0));
    }
    b.aabox(v(4.85, 0.0, 0.3), v(5.15, 3.0, 4.0));
    b.aabox(v(4.85, 0.0, 5.0), v(5.15, 3.0, 9.7));
    b.aabox(v(4.85, 2.2, 4.0), v(5.15, 3.0, 5.0));
    b.aabox(v(6.0, 0.0, 6.0), v(9.7, 3.0, 9.7));
    b.build()
}

/// A picket fence in front of small objects, sized in texels of a cube map of resolution `r` seen
/// from the grid's middle: bars 0.25, 0.5, 1, 2, 4, 8 texels wide (cycled), gaps 0.5–4 bars wide,
/// 10 units from the grid's far edge; behind it 40 posts and boxes, 0.1–0.8 wide, then a back
/// wall. The ground is a slab. Returns the scene and its grid (4 × 1 × 4 cells of 2 × 0.5 × 2).
pub fn picket_fence(r: u32) -> (Scene, ViewGrid) {
    let mut b = SceneBuilder::default();
    b.aabox(Vec3::new(-30.0, -1.0, -10.0), Vec3::new(40.0, 0.0, 50.0));
    let grid = ViewGrid::new(Aabb::new(Vec3::new(0.0, 1.5, 0.0), Vec3::new(8.0, 2.0, 8.0)), [4, 1, 4]);
    let fence_z = 18.0;
    // One texel at the face centre, seen from the grid's middle (z = 4): 2/R radians.
    let texel = (fence_z - 4.0) * 2.0 / r as f32;
    let widths = [0.25, 0.5, 1.0, 2.0, 4.0, 8.0];
    let mut rng = Rng(7);
    let (mut x, mut i) = (-20.0f32, 0);
    while x < 28.0 {
        let w = widths[i % widths.len()] * texel;
        b.aabox(Vec3::new(x, 0.0, fence_z), Vec3::new(x + w, 3.0, fence_z + 0.05));
        x += w + rng.range(0.5, 4.0) * w.max(texel);
        i += 1;
    }
    for _ in 0..40 {
        let (px, pz) = (rng.range(-15.0, 23.0), rng.range(fence_z + 1.0, fence_z + 14.0));
        let (w, h) = (rng.range(0.1, 0.8), rng.range(0.5, 2.8));
        b.aabox(Vec3::new(px, 0.0, pz), Vec3::new(px + w, h, pz + w));
    }
    b.aabox(Vec3::new(-30.0, 0.0, fence_z + 16.0), Vec3::new(40.0, 5.0, fence_z + 16.5));
    (b.build(), grid)
}

/// The street block of the from-region audits ([`city_block`] with props) and its grid: eye-height
/// cells of 5 × 0.5 × 5 over the middle of the block, streets and buildings alike.
pub fn audit_block() -> (Scene, ViewGrid) {
    let grid = ViewGrid::new(Aabb::new(Vec3::new(20.0, 1.5, 20.0), Vec3::new(80.0, 2.0, 80.0)), [12, 1, 12]);
    (city_block(6, true), grid)
}

/// The from-region audit scenes by name, with their grids: `street` ([`street_with_gaps`]),
/// `audit` ([`audit_block`]), `fence` ([`picket_fence`], its bars sized for cube maps of
/// resolution `r`) or `city` (the default generated city, seed 1).
pub fn audit_scene(name: &str, r: u32) -> Result<(Scene, ViewGrid), String> {
    Ok(match name {
        "street" => street_with_gaps(),
        "audit" => audit_block(),
        "fence" => picket_fence(r),
        "city" => {
            let params = hdov::city::CityParams { seed: 1, ..Default::default() };
            let scene = hdov::city::generate(&params).map_err(|e| e.to_string())?;
            let grid = scene.grid.clone().ok_or("the city brings a grid")?;
            (scene, grid)
        }
        other => return Err(format!("unknown scene '{other}': street, audit, fence or city")),
    })
}

/// The tiny generated city (default seed) built into `dir/db` with the CPU backend at R = 16:
/// a whole database in about a second. Returns the scene and the database's directory.
pub fn tiny_city_database(dir: &std::path::Path) -> (Scene, std::path::PathBuf) {
    let params = hdov::city::CityParams { scale: hdov::city::CityScale::Tiny, ..Default::default() };
    let scene = hdov::city::generate(&params).unwrap();
    let visibility = hdov::VisibilityParams { resolution: 16, backend: hdov::BackendKind::Cpu, ..Default::default() };
    let build = hdov::BuildParams { visibility: Some(visibility), ..Default::default() };
    let db = dir.join("db");
    hdov::build(&scene, &db, &build, hdov::Overwrite::Never, &hdov::Progress::hidden()).unwrap();
    (scene, db)
}
