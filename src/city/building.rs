//! Procedural building designs: houses and towers of a few hundred to 1,800 triangles.
//!
//! The sizes follow the thesis's base models (Table 3.1: houses of 240–1,812 polygons, towers of
//! 540–1,702). A building is modelled in its own frame: footprint centred on the origin, ground at
//! y = 0, nothing outside the footprint rectangle it was given (ledges and eaves included), so
//! the layout can keep buildings apart by keeping their lots apart.

use glam::Vec2;

use super::builder::{MeshBuilder, Rect, Tier, Windows};
use crate::rng::Rng;
use crate::scene::Mesh;

/// Fewest triangles a building may have.
pub const MIN_TRIANGLES: usize = 240;
/// Most triangles a building may have.
pub const MAX_TRIANGLES: usize = 1800;

/// What kind of building a lot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildingKind {
    /// Two to four storeys, pitched or flat roof, 6–15 m tall.
    House,
    /// A podium, one to three setback tiers and a roof crown, 30–150 m tall.
    Tower,
}

impl BuildingKind {
    /// The kind's name, as reports print it.
    pub fn name(self) -> &'static str {
        match self {
            BuildingKind::House => "house",
            BuildingKind::Tower => "tower",
        }
    }
}

/// The roof of a house.
#[derive(Clone, Copy, Debug)]
enum HouseRoof {
    Gable {
        along_x: bool,
    },
    Hip {
        along_x: bool,
    },
    /// A flat roof behind a parapet, with the top storey set back when there are three or more.
    Flat,
}

/// How a tower's facades are glazed.
#[derive(Clone, Copy, Debug)]
enum Glazing {
    /// Punched windows in rows and columns.
    Grid,
    /// Continuous horizontal window bands, one per row.
    Ribbons,
    /// Tall vertical glass bays between piers.
    Bays,
}

/// The crown of a tower.
#[derive(Clone, Copy, Debug)]
enum Crown {
    /// Parapet, plant room and a mast.
    Mast,
    /// A pyramid spire over a last narrow tier.
    Spire,
}

/// Every random choice of one house, drawn once so that re-building it at another window density
/// changes only the windows.
#[derive(Clone, Debug)]
struct HouseDesign {
    size: Vec2,
    wall_height: f32,
    floors: u32,
    roof: HouseRoof,
    roof_height: f32,
    window_spacing: f32,
    chimney: Vec2,
}

/// Every random choice of one tower.
#[derive(Clone, Debug)]
struct TowerDesign {
    size: Vec2,
    podium_height: f32,
    /// Footprint and height of each tier above the podium, bottom up.
    tiers: Vec<(Rect, f32)>,
    glazing: Glazing,
    crown: Crown,
    crown_height: f32,
}

/// Builds one building that fits in a `size` footprint (x by z, centred on the origin) and is
/// about `height` tall, with its triangle count in `MIN_TRIANGLES..=MAX_TRIANGLES`.
///
/// Cost: a few windows-density trials of a mesh of at most 1,800 triangles (tens of µs).
pub fn building_mesh(kind: BuildingKind, size: Vec2, height: f32, rng: &mut Rng) -> Mesh {
    let start_density = rng.range(0.6, 1.5);
    match kind {
        BuildingKind::House => {
            let design = house_design(size, height, rng);
            fit_budget(start_density, |d| build_house(&design, d))
        }
        BuildingKind::Tower => {
            let design = tower_design(size, height, rng);
            fit_budget(start_density, |d| build_tower(&design, d))
        }
    }
}

/// Re-builds at lower or higher window density until the triangle count is within budget.
/// Each step scales window columns and rows by 1.25, about 1.5 times the triangles, well inside
/// the budget's ratio of 7.5, so the search cannot jump over it.
fn fit_budget(start_density: f32, build: impl Fn(f32) -> MeshBuilder) -> Mesh {
    let mut density = start_density;
    let mut built = build(density);
    for _ in 0..64 {
        let n = built.triangle_count();
        if n > MAX_TRIANGLES {
            density /= 1.25;
        } else if n < MIN_TRIANGLES {
            density *= 1.25;
        } else {
            break;
        }
        built = build(density);
    }
    built.finish()
}

/// Window count for a run of `length` metres at one window per `spacing`, scaled by `density`.
fn window_count(length: f32, spacing: f32, density: f32, max: u32) -> u32 {
    ((length / spacing * density).round() as u32).clamp(1, max)
}

fn house_design(size: Vec2, height: f32, rng: &mut Rng) -> HouseDesign {
    let along_x = size.x >= size.y;
    let roof = match rng.int(0, 2) {
        0 => HouseRoof::Gable { along_x },
        1 => HouseRoof::Hip { along_x },
        _ => HouseRoof::Flat,
    };
    let roof_height = match roof {
        HouseRoof::Flat => 0.0,
        _ => (size.min_element() * rng.range(0.25, 0.4)).clamp(1.5, 5.0),
    };
    let wall_height = (height - roof_height).max(3.2);
    let floors = ((wall_height / 3.0).floor() as u32).max(1);
    let body = size - Vec2::splat(2.0 * EAVE);
    let chimney = Vec2::new(rng.range(-0.3, 0.3) * body.x, rng.range(-0.3, 0.3) * body.y);
    HouseDesign { size, wall_height, floors, roof, roof_height, window_spacing: rng.range(2.2, 3.5), chimney }
}

/// Overhang of eaves and cornices beyond a house's walls.
const EAVE: f32 = 0.4;

/// A house: plinth, walls with a window per bay and storey, string courses between storeys, a
/// cornice, then a gable, hip or flat roof (with parapet and set-back top storey) and a chimney.
fn build_house(h: &HouseDesign, density: f32) -> MeshBuilder {
    let mut b = MeshBuilder::new();
    let outer = Rect::centered(h.size);
    let body = outer.grown(-EAVE);
    let windows = |rect: Rect, rows: u32| Windows {
        cols: [
            window_count(rect.size().x, h.window_spacing, density, 14),
            window_count(rect.size().y, h.window_spacing, density, 14),
        ],
        rows,
        width_frac: 0.45,
        height_frac: 0.5,
        depth: 0.25,
    };
    let setback_top = matches!(h.roof, HouseRoof::Flat) && h.floors >= 3;
    let main_floors = if setback_top { h.floors - 1 } else { h.floors };
    let storey = h.wall_height / h.floors as f32;
    let main_top = storey * main_floors as f32;
    b.cuboid(body.grown(0.15), 0.0, 0.5);
    b.tier(&Tier { footprint: body, y0: 0.0, y1: main_top, windows: windows(body, main_floors) });
    for floor in 1..main_floors {
        let y = storey * floor as f32;
        b.cuboid(body.grown(0.12), y - 0.1, y + 0.1);
    }
    b.cuboid(body.grown(EAVE), main_top - 0.35, main_top);
    match h.roof {
        HouseRoof::Gable { along_x } => b.gable_roof(outer, main_top, h.roof_height, along_x),
        HouseRoof::Hip { along_x } => b.hip_roof(outer, main_top, h.roof_height, along_x, h.size.min_element() * 0.4),
        HouseRoof::Flat => {
            b.parapet(body, main_top, 0.9, 0.3);
            if setback_top {
                let top = body.grown(-1.8);
                b.tier(&Tier { footprint: top, y0: main_top, y1: h.wall_height, windows: windows(top, 1) });
                b.cuboid(top.grown(0.25), h.wall_height - 0.3, h.wall_height);
            }
        }
    }
    let chimney = Rect::new(h.chimney - Vec2::splat(0.35), h.chimney + Vec2::splat(0.35));
    b.cuboid(chimney, main_top - 0.5, h.wall_height + h.roof_height + 0.6);
    b
}

fn tower_design(size: Vec2, height: f32, rng: &mut Rng) -> TowerDesign {
    let crown = if rng.chance(0.3) { Crown::Spire } else { Crown::Mast };
    let crown_height = match crown {
        Crown::Spire => (height * rng.range(0.08, 0.15)).clamp(4.0, 18.0),
        Crown::Mast => 0.0,
    };
    let podium_height = rng.range(4.5, 8.0);
    let shaft_height = height - crown_height - podium_height;
    // Taller towers step back more often; each tier needs a shaft of at least 8 m a side.
    let max_tiers = if height > 90.0 {
        3
    } else if height > 50.0 {
        2
    } else {
        1
    };
    let tier_count = rng.int(1, max_tiers);
    let shares: &[f32] = match tier_count {
        1 => &[1.0],
        2 => &[0.62, 0.38],
        _ => &[0.5, 0.3, 0.2],
    };
    let mut footprint = Rect::centered(size).grown(-TOWER_LEDGE - rng.range(0.0, 1.5));
    let mut tiers = Vec::new();
    let mut y = podium_height;
    for (k, share) in shares.iter().enumerate() {
        if k > 0 {
            let setback = rng.range(1.5, 4.0).min((footprint.size().min_element() - 8.0) * 0.5);
            footprint = footprint.grown(-setback.max(0.0));
        }
        let tier_height = shaft_height * share;
        tiers.push((footprint, tier_height));
        y += tier_height;
    }
    debug_assert!((y + crown_height - height).abs() < 1e-3 * height);
    let glazing = match rng.int(0, 2) {
        0 => Glazing::Grid,
        1 => Glazing::Ribbons,
        _ => Glazing::Bays,
    };
    TowerDesign { size, podium_height, tiers, glazing, crown, crown_height }
}

/// Overhang of a tower's ledges beyond the tier below them.
const TOWER_LEDGE: f32 = 0.5;

/// A tower: a podium with shop windows, setback tiers each capped by a ledge, and a crown
/// (parapet, plant room and mast, or a spire).
fn build_tower(t: &TowerDesign, density: f32) -> MeshBuilder {
    let mut b = MeshBuilder::new();
    let podium = Rect::centered(t.size).grown(-TOWER_LEDGE);
    let shop_windows = Windows {
        cols: [window_count(podium.size().x, 5.0, density, 10), window_count(podium.size().y, 5.0, density, 10)],
        rows: 1,
        width_frac: 0.75,
        height_frac: 0.7,
        depth: 0.4,
    };
    b.tier(&Tier { footprint: podium, y0: 0.0, y1: t.podium_height, windows: shop_windows });
    b.cuboid(podium.grown(TOWER_LEDGE), t.podium_height - 0.6, t.podium_height);
    let mut y = t.podium_height;
    for &(footprint, tier_height) in &t.tiers {
        let floors = tier_height / 3.5;
        let size = footprint.size();
        let (spacing, rows, width_frac, height_frac) = match t.glazing {
            Glazing::Grid => (3.0, floors, 0.5, 0.55),
            Glazing::Ribbons => (f32::INFINITY, floors, 0.92, 0.45),
            Glazing::Bays => (2.6, floors / 4.0, 0.6, 0.9),
        };
        let windows = Windows {
            cols: [window_count(size.x, spacing, density, 16), window_count(size.y, spacing, density, 16)],
            rows: ((rows * density).round() as u32).clamp(1, 48),
            width_frac,
            height_frac,
            depth: 0.35,
        };
        b.tier(&Tier { footprint, y0: y, y1: y + tier_height, windows });
        y += tier_height;
        b.cuboid(footprint.grown(TOWER_LEDGE), y - 0.8, y);
    }
    let (roof, _) = *t.tiers.last().expect("a tower has at least one tier");
    match t.crown {
        Crown::Mast => {
            b.parapet(roof, y, 1.2, 0.4);
            let plant = Rect::centered(roof.size() * 0.4);
            let plant_windows = Windows { cols: [1, 1], rows: 1, width_frac: 0.6, height_frac: 0.5, depth: 0.2 };
            b.tier(&Tier { footprint: plant, y0: y, y1: y + 4.0, windows: plant_windows });
            b.cuboid(Rect::centered(Vec2::splat(0.5)), y + 4.0, y + 4.0 + (t.size.min_element() * 0.5).min(12.0));
        }
        Crown::Spire => b.pyramid(roof.grown(-0.5), y, t.crown_height),
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buildings_stay_in_budget_and_footprint() {
        let mut rng = Rng::new(11);
        for i in 0..400 {
            let tower = i % 2 == 0;
            let (kind, size, height) = if tower {
                (BuildingKind::Tower, Vec2::new(rng.range(16.0, 40.0), rng.range(16.0, 40.0)), rng.range(30.0, 150.0))
            } else {
                (BuildingKind::House, Vec2::new(rng.range(7.0, 20.0), rng.range(7.0, 20.0)), rng.range(6.0, 15.0))
            };
            let mesh = building_mesh(kind, size, height, &mut rng);
            let n = mesh.triangle_count();
            assert!((MIN_TRIANGLES..=MAX_TRIANGLES).contains(&n), "{kind:?} {size} x {height}: {n} triangles");
            let bounds = mesh.bounds();
            let half = size * 0.5 + Vec2::splat(1e-3);
            assert!(bounds.min.x >= -half.x && bounds.max.x <= half.x, "{kind:?} x {bounds:?} for {size}");
            assert!(bounds.min.z >= -half.y && bounds.max.z <= half.y, "{kind:?} z {bounds:?} for {size}");
            assert!(bounds.min.y == 0.0, "{kind:?} stands on the ground");
            let top = bounds.max.y;
            match kind {
                BuildingKind::House => assert!((5.0..=17.0).contains(&top), "house {top} m"),
                BuildingKind::Tower => assert!((28.0..=172.0).contains(&top), "tower {top} m"),
            }
        }
    }
}
