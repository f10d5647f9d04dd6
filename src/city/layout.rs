//! The city plan: streets, blocks, lots, plazas, and where each building and statue stands.
//!
//! The city lies in x ∈ [0, width], z ∈ [0, depth] on the ground plane (y up). Streets run along
//! both axes, including a ring around the outside; between them lie blocks. A few blocks are
//! plazas holding instances of the detail model; the others are cut into lots by alternating
//! guillotine splits, each lot holding one building set back from the lot's edges. Buildings
//! are taller towards the centre, where towers are also more common ("downtown").

use glam::Vec2;

use super::builder::Rect;
use super::building::BuildingKind;
use crate::rng::Rng;

/// Independent random streams, so that e.g. changing the lot splitter leaves street widths as
/// they were.
const STREETS: u64 = 1;
const PLAZAS: u64 = 2;
const BLOCKS: u64 = 3;

/// Width of the sidewalk between a block's edge and its lots, in metres.
const SIDEWALK: f32 = 3.0;
/// Lots longer than this on a side are split again, in metres.
const MAX_LOT_SIDE: f32 = 32.0;
/// Gap between a building and its lot's edge: neighbours stand at least twice this apart.
const LOT_MARGIN: f32 = 1.0;
/// Fraction of blocks that are plazas (at least one per city).
const PLAZA_FRACTION: f32 = 0.07;
/// Detail-model instances per plaza, on a 3 × 2 grid.
const DETAILS_PER_PLAZA: usize = 6;

/// One building to generate and place.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildingSite {
    pub kind: BuildingKind,
    /// Footprint centre on the ground plane (x, z).
    pub centre: Vec2,
    /// Footprint size (x, z) in the building's own frame.
    pub size: Vec2,
    pub height: f32,
    /// Whether the building is turned half a turn (its own frame's +z facing the world's -z).
    pub turned: bool,
}

/// One instance of the detail model.
#[derive(Clone, Debug, PartialEq)]
pub struct DetailSite {
    pub position: Vec2,
    /// Rotation about y, in radians.
    pub yaw: f32,
    pub scale: f32,
}

/// The whole plan.
#[derive(Clone, Debug, PartialEq)]
pub struct CityPlan {
    /// The city's extent (x, z), streets included, from the origin.
    pub extent: Vec2,
    pub buildings: Vec<BuildingSite>,
    pub details: Vec<DetailSite>,
}

/// Lays out a city of `blocks` (along x, along z; each at least 1) for `seed`. A city of one
/// block has no plaza; its statues stand in the corner crossings of its ring street.
pub fn plan_city(seed: u64, blocks: [u32; 2]) -> CityPlan {
    let blocks = blocks.map(|b| b.max(1));
    let mut streets = Rng::derive(seed, STREETS, 0);
    let columns = street_grid(blocks[0], &mut streets);
    let rows = street_grid(blocks[1], &mut streets);
    let extent = Vec2::new(columns.1, rows.1);
    let block_count = (blocks[0] * blocks[1]) as usize;
    let plazas = choose_plazas(seed, block_count);
    let mut buildings = Vec::new();
    let mut details = Vec::new();
    for (index, is_plaza) in plazas.iter().enumerate() {
        let (bx, bz) = (index % blocks[0] as usize, index / blocks[0] as usize);
        let (x0, x1) = columns.0[bx];
        let (z0, z1) = rows.0[bz];
        let block = Rect::new(Vec2::new(x0, z0), Vec2::new(x1, z1));
        let mut rng = Rng::derive(seed, BLOCKS, index as u64);
        if *is_plaza {
            details.extend(plaza_details(block, &mut rng));
        } else {
            let downtown = downtown_factor(block.center(), extent);
            let mut lots = Vec::new();
            split_into_lots(block.grown(-SIDEWALK), downtown, &mut rng, &mut lots);
            buildings.extend(lots.iter().map(|lot| site_on_lot(*lot, downtown, &mut rng)));
        }
    }
    if details.is_empty() {
        details = corner_details(
            Rect::new(Vec2::new(columns.0[0].0, rows.0[0].0), Vec2::new(columns.0[0].1, rows.0[0].1)),
            extent,
            seed,
        );
    }
    CityPlan { extent, buildings, details }
}

/// Statues for a city too small for a plaza (one block): one in each corner crossing of the
/// ring street around `block`.
fn corner_details(block: Rect, extent: Vec2, seed: u64) -> Vec<DetailSite> {
    let mut rng = Rng::derive(seed, PLAZAS, 1);
    let xs = [block.min.x * 0.5, (block.max.x + extent.x) * 0.5];
    let zs = [block.min.y * 0.5, (block.max.y + extent.y) * 0.5];
    let corners = [Vec2::new(xs[0], zs[0]), Vec2::new(xs[1], zs[0]), Vec2::new(xs[1], zs[1]), Vec2::new(xs[0], zs[1])];
    corners
        .into_iter()
        .map(|position| DetailSite {
            position,
            yaw: rng.range(0.0, std::f32::consts::TAU),
            scale: rng.range(0.8, 1.25),
        })
        .collect()
}

/// The block intervals along one axis and the total length: streets of 10–16 m, an avenue of
/// 18–22 m every fourth line, blocks of 60–120 m. Block lengths are stratified (one drawn from
/// each of `blocks` equal slices of the range, then shuffled) so that a city's size, and with it
/// its object count, varies little between seeds while its blocks still vary.
fn street_grid(blocks: u32, rng: &mut Rng) -> (Vec<(f32, f32)>, f32) {
    let street_width =
        |line: u32, rng: &mut Rng| if line.is_multiple_of(4) { rng.range(18.0, 22.0) } else { rng.range(10.0, 16.0) };
    let slice = 60.0 / blocks as f32;
    let mut lengths: Vec<f32> = (0..blocks).map(|k| 60.0 + slice * (k as f32 + rng.unit())).collect();
    for k in (1..lengths.len()).rev() {
        lengths.swap(k, (rng.next_u64() % (k as u64 + 1)) as usize);
    }
    let mut at = street_width(0, rng);
    let mut intervals = Vec::with_capacity(blocks as usize);
    for (line, length) in (1..=blocks).zip(lengths) {
        intervals.push((at, at + length));
        at += length + street_width(line, rng);
    }
    (intervals, at)
}

/// Which blocks are plazas: `PLAZA_FRACTION` of them, at least one, but none in a city of one
/// block (its statues stand at the street corners instead), picked by a partial Fisher–Yates
/// shuffle.
fn choose_plazas(seed: u64, block_count: usize) -> Vec<bool> {
    let wanted = ((block_count as f32 * PLAZA_FRACTION).round() as usize).max(1).min(block_count - 1);
    let mut rng = Rng::derive(seed, PLAZAS, 0);
    let mut order: Vec<usize> = (0..block_count).collect();
    let mut plazas = vec![false; block_count];
    for k in 0..wanted {
        let pick = k + (rng.next_u64() % (block_count - k) as u64) as usize;
        order.swap(k, pick);
        plazas[order[k]] = true;
    }
    plazas
}

/// 1 at the city's centre, falling to 0 at its corners.
fn downtown_factor(at: Vec2, extent: Vec2) -> f32 {
    let half = extent * 0.5;
    (1.0 - (at - half).length() / half.length()).clamp(0.0, 1.0)
}

/// Cuts `rect` across its longer side at 35–65 % until no side exceeds [`MAX_LOT_SIDE`]. Downtown,
/// a lot of up to 1.5 times that may be kept whole, room for a tower.
fn split_into_lots(rect: Rect, downtown: f32, rng: &mut Rng, lots: &mut Vec<Rect>) {
    let size = rect.size();
    let longer = size.max_element();
    let keep_large = longer <= MAX_LOT_SIDE * 1.5 && rng.chance(0.4 * downtown);
    if longer <= MAX_LOT_SIDE || keep_large {
        lots.push(rect);
        return;
    }
    let cut = rng.range(0.35, 0.65);
    let (a, b) = if size.x >= size.y {
        let x = rect.min.x + size.x * cut;
        (Rect::new(rect.min, Vec2::new(x, rect.max.y)), Rect::new(Vec2::new(x, rect.min.y), rect.max))
    } else {
        let z = rect.min.y + size.y * cut;
        (Rect::new(rect.min, Vec2::new(rect.max.x, z)), Rect::new(Vec2::new(rect.min.x, z), rect.max))
    };
    split_into_lots(a, downtown, rng, lots);
    split_into_lots(b, downtown, rng, lots);
}

/// The building on one lot: a tower (16–40 m a side, 30–150 m tall, likelier and taller
/// downtown) where the lot is big enough and chance says so, else a house (7–20 m a side,
/// 6–15 m tall). Either is centred on the lot inside a [`LOT_MARGIN`].
fn site_on_lot(lot: Rect, downtown: f32, rng: &mut Rng) -> BuildingSite {
    let room = lot.size() - Vec2::splat(2.0 * LOT_MARGIN);
    let tower_chance = 0.08 + 0.6 * downtown * downtown;
    let turned = rng.chance(0.5);
    if room.min_element() >= 16.0 && rng.chance(tower_chance) {
        let size = room.min(Vec2::splat(40.0));
        let tallness = rng.unit().powf(1.5) * (0.35 + 0.65 * downtown);
        let height = 30.0 + 120.0 * tallness;
        BuildingSite { kind: BuildingKind::Tower, centre: lot.center(), size, height, turned }
    } else {
        let size = Vec2::new(rng.range(9.0, 20.0), rng.range(9.0, 20.0)).min(room).max(Vec2::splat(7.0));
        let height = rng.range(6.0, 15.0);
        BuildingSite { kind: BuildingKind::House, centre: lot.center(), size, height, turned }
    }
}

/// Statues on a 3 × 2 grid over the plaza (the 3 along its longer side), each jittered by up to
/// 2 m, turned at random and scaled by 0.8–1.25.
fn plaza_details(block: Rect, rng: &mut Rng) -> Vec<DetailSite> {
    let inner = block.grown(-10.0);
    let size = inner.size();
    let counts = if size.x >= size.y { [3, 2] } else { [2, 3] };
    let mut sites = Vec::with_capacity(DETAILS_PER_PLAZA);
    for j in 0..counts[1] {
        for i in 0..counts[0] {
            let cell = Vec2::new((i as f32 + 0.5) / counts[0] as f32, (j as f32 + 0.5) / counts[1] as f32);
            let jitter = Vec2::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
            let position = inner.min + size * cell + jitter;
            sites.push(DetailSite {
                position,
                yaw: rng.range(0.0, std::f32::consts::TAU),
                scale: rng.range(0.8, 1.25),
            });
        }
    }
    sites
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lots_tile_the_block_inside_the_sidewalk() {
        let mut rng = Rng::new(3);
        for _ in 0..50 {
            let block = Rect::new(Vec2::ZERO, Vec2::new(rng.range(60.0, 120.0), rng.range(60.0, 120.0)));
            let inner = block.grown(-SIDEWALK);
            let mut lots = Vec::new();
            split_into_lots(inner, rng.unit(), &mut rng, &mut lots);
            let area: f32 = lots.iter().map(|l| l.size().x * l.size().y).sum();
            let inner_area = inner.size().x * inner.size().y;
            assert!((area - inner_area).abs() < 1e-2 * inner_area, "lots cover {area} of {inner_area}");
            for lot in &lots {
                assert!(lot.size().max_element() <= MAX_LOT_SIDE * 1.5 + 1e-3, "{lot:?}");
                assert!(lot.size().min_element() >= 8.0, "{lot:?}");
            }
        }
    }

    #[test]
    fn plazas_are_a_few_and_never_all() {
        assert_eq!(choose_plazas(1, 1), vec![false]);
        assert_eq!(choose_plazas(1, 2).iter().filter(|p| **p).count(), 1);
        assert_eq!(choose_plazas(1, 729).iter().filter(|p| **p).count(), 51);
    }
}
