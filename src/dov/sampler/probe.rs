//! Ray probing: from-region visibility by rays aimed at objects (the directional form of guided
//! visibility sampling, Wonka et al. 2006), instead of more whole cube maps.
//!
//! The cell's corners are measured anyway and say what they see. The objects a cell could also
//! see are few and known beforehand: those its neighbours' corners see (views change
//! continuously, so an object seen just outside the cell is the likeliest to be seen from part of
//! it) and those whose box meets the cell. For each such *candidate* that no corner sees, rays go
//! from `points` well-spread points of the cell towards points spread over the candidate's surface
//! ([`SurfaceTargets`]), `rays` per point, until one meets the candidate first: it is then seen,
//! from that point, for certain. Any other unseen object such a ray meets first is seen too. A
//! seen object's DoV is measured at the probe point whose rays meet it most, on the cube map's own
//! texels there, only those whose centre ray enters the object's box (its *footprint*), so it is
//! the DoV a whole cube map at that point would give that object. Each probe point's findings
//! become a partial point view ([`CellProbe::points`]) that the cell's DoV takes its max over,
//! like any measured point's.
//!
//! Cost: at most candidates × `points` × `rays` rays plus the footprints of what is found, against
//! 6·R² rays per cube map; a candidate hidden from the whole cell costs all its rays (nothing
//! proves it hidden earlier), so the hidden candidates set the price.
//!
//! An object seen only through a gap narrower than the spacing of its targets, or only from
//! places between the probe points, can still be missed: the audit in docs/journal/dov-sampling.md (§2) measures how
//! often against dense sampling. *Region rays* (`RayProbing::region`) close most of that: rays
//! from all over the cell in every direction ([`region_finds`]); what they meet is seen, and what
//! the neighbouring cells' region rays meet becomes a candidate here (`precompute`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::time::Instant;


use glam::Vec3;
use rayon::prelude::*;

use super::{CellSampler, CellSite, Tally};
use crate::dov::cubemap::{FACE_COUNT, face_basis, uv_direction};
use crate::dov::rays::RayCaster;
use crate::dov::sampling::{RegionRays, RegionSequence, RegionViews, halton_point, seen_by};
use crate::dov::{BACK_FACE_BIT, CubeMap, DovBackend, NO_OBJECT, PointDov};
use crate::error::{Error, Param, Result};
use crate::format::BakePhases;
use crate::format::sampling::RayProbing;
use crate::geom::Aabb;
use crate::grid::{ViewCell, ViewGrid, places_around};

/// How far past its target a probe ray looks, in lengths of the ray to the target: the target lies
/// on the object's surface, so a ray that meets the object meets it by then (the margin is for
/// rounding); what lies behind cannot change the answer.
const TARGET_REACH: f32 = 1.001;

/// The probe points of a cell and how rays go from them towards objects' targets.
struct Aim<'a> {
    rays: &'a dyn RayCaster,
    points: &'a [Vec3],
    /// The points outside geometry (only those cast), in point order.
    outside: &'a [usize],
    per_point: usize,
    /// How many points search for a candidate seen nearby ([`RayProbing::nearest`]).
    nearest: usize,
}

impl Aim<'_> {
    /// The rays from point `i` towards each of `objects`' targets (`per_point` each: point `i`
    /// takes its own targets), traced together ([`RayCaster::first_hits_from`]): for each ray,
    /// the object it was aimed at and the id it met first.
    fn rays_from_point(&self, i: usize, objects: &[u32]) -> Vec<(u32, u32)> {
        let p = self.points[i];
        let targets = self.rays.targets();
        let (mut rays, mut aimed_at) = (Vec::new(), Vec::new());
        for &object in objects {
            for j in 0..self.per_point {
                let d = targets.target(object, i * self.per_point + j) - p;
                if d.length_squared() > 0.0 {
                    rays.push((d, TARGET_REACH));
                    aimed_at.push(object);
                }
            }
        }
        let ids = self.rays.first_hits_from(p, &rays);
        aimed_at.into_iter().zip(ids).collect()
    }

    /// Searches for `candidates` (those not `seen` nor `settled`), each from its own points:
    /// the `nearest` points outside geometry nearest the places it was seen from, or every one
    /// for a candidate with no such place; [`AIM_ROUND`] points a round, each
    /// point's rays at all the candidates it aims at that round traced together, until every
    /// candidate has been met (its rays' first hit is the candidate, front or back) or has used
    /// its points. Returns each unseen object that a ray met first, with the point the ray came
    /// from (a candidate's rays may meet others first), and the rays cast.
    fn search(&self, candidates: &[Candidate], seen: &HashSet<u32>, settled: &HashSet<u32>) -> (Vec<(u32, usize)>, u64) {
        let mut left: Vec<(u32, Vec<usize>)> = candidates
            .iter()
            .filter(|c| !seen.contains(&c.object) && !settled.contains(&c.object))
            .map(|c| (c.object, self.guided_points(&c.seen_from)))
            .collect();
        let (mut met, mut cast) = (Vec::new(), 0u64);
        for round in 0.. {
            // Each point's candidates this round, by point.
            let mut by_point: BTreeMap<usize, Vec<u32>> = BTreeMap::new();
            for (object, points) in &left {
                for &i in points.iter().skip(round * AIM_ROUND).take(AIM_ROUND) {
                    by_point.entry(i).or_default().push(*object);
                }
            }
            if by_point.is_empty() {
                break;
            }
            let hits: Vec<(usize, Vec<(u32, u32)>)> =
                by_point.into_par_iter().map(|(i, objects)| (i, self.rays_from_point(i, &objects))).collect();
            let mut reached = HashSet::new();
            for (i, rays) in hits {
                cast += rays.len() as u64;
                for (aimed_at, id) in rays {
                    let object = id & !BACK_FACE_BIT;
                    if id != NO_OBJECT && !seen.contains(&object) {
                        met.push((object, i));
                    }
                    if object == aimed_at {
                        reached.insert(aimed_at);
                    }
                }
            }
            left.retain(|c| !reached.contains(&c.0));
        }
        (met, cast)
    }

    /// The points outside geometry that aim at a candidate seen from `seen_from`: the `nearest`
    /// ones nearest any of those places, nearest first (among equals, in point order); every
    /// one, in point order, where it is empty. Views change continuously, so a
    /// part of the cell that sees what a neighbour's corner or ray saw is likeliest near it.
    fn guided_points(&self, seen_from: &[Vec3]) -> Vec<usize> {
        if seen_from.is_empty() {
            return self.outside.to_vec();
        }
        let distance = |i: usize| seen_from.iter().map(|q| q.distance_squared(self.points[i])).fold(f32::INFINITY, f32::min);
        let mut order: Vec<(f32, usize)> = self.outside.iter().map(|&i| (distance(i), i)).collect();
        order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        order.into_iter().take(self.nearest).map(|(_, i)| i).collect()
    }

    /// For each of `objects`, how many of each point's rays at it meet it first (front or back),
    /// point by point; and the rays cast.
    fn hits_by_point(&self, objects: &[u32]) -> (Vec<Vec<u32>>, u64) {
        let slot: HashMap<u32, usize> = objects.iter().enumerate().map(|(k, &o)| (o, k)).collect();
        let traced: Vec<(usize, Vec<(u32, u32)>)> =
            self.outside.par_iter().map(|&i| (i, self.rays_from_point(i, objects))).collect();
        let mut hits = vec![vec![0u32; self.points.len()]; objects.len()];
        let mut cast = 0;
        for (i, rays) in traced {
            cast += rays.len() as u64;
            for (aimed_at, id) in rays {
                if id & !BACK_FACE_BIT == aimed_at {
                    hits[slot[&aimed_at]][i] += 1;
                }
            }
        }
        (hits, cast)
    }
}

/// Probe points whose aimed rays go out together before the candidates they met are dropped: a
/// candidate seen from the first points costs few rays, and a round's rays at all its
/// candidates trace together.
const AIM_ROUND: usize = 4;

/// An object to probe for, and where nearby it was seen from (the neighbouring cells' corners
/// and region rays' origins that met it); none when it is a candidate because its box meets the
/// cell.
#[derive(Clone, Debug, Default)]
pub struct Candidate {
    pub object: u32,
    pub seen_from: Vec<Vec3>,
}

/// Directions from a point for telling whether it lies inside geometry: the 26 neighbours of a
/// cube's centre.
fn inside_test_directions() -> impl Iterator<Item = Vec3> {
    (0..27)
        .filter(|&i| i != 13)
        .map(|i| Vec3::new((i % 3) as f32 - 1.0, (i / 3 % 3) as f32 - 1.0, (i / 9) as f32 - 1.0))
}

/// Whether `p` sees mostly back faces (inside a closed mesh): such points are left out, as
/// [`crate::dov::sampling::is_inside`] leaves out measured ones.
fn is_inside(rays: &dyn RayCaster, p: Vec3) -> bool {
    let (mut back, mut hits) = (0, 0);
    let directions: Vec<(Vec3, f32)> = inside_test_directions().map(|d| (d, f32::INFINITY)).collect();
    for id in rays.first_hits_from(p, &directions) {
        hits += usize::from(id != NO_OBJECT);
        back += usize::from(id != NO_OBJECT && id & BACK_FACE_BIT != 0);
    }
    2 * back > hits.max(1)
}

/// What probing one cell found and cost.
#[derive(Debug, Default)]
pub struct CellProbe {
    /// One partial point view per probe point that found something: the DoVs of the objects
    /// found from it, measured on their footprints (the point's other objects are left out).
    pub points: Vec<PointDov>,
    /// Where each of `points` was measured from.
    pub at: Vec<Vec3>,
    /// Rays cast towards targets (and to tell inside points).
    pub rays: u64,
    /// Rays cast to measure the footprints of what was found.
    pub footprint_rays: u64,
    /// Seconds of its search, hit counts and footprints.
    pub phases: BakePhases,
}

/// What a cell's probing starts from.
pub struct Leads<'a> {
    /// The objects its measured points see (not probed).
    pub seen: &'a std::collections::HashSet<u32>,
    /// The objects to probe.
    pub candidates: &'a [Candidate],
    /// What the cell's own region rays met.
    pub region: &'a [RegionFind],
}

/// An object that a cell's region (or border) rays met: with the origin of the first ray that
/// met it, and the squares of the cell ([`ViewCell::square_of`]) whose rays met it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegionFind {
    pub object: u32,
    pub origin: Vec3,
    pub squares: u64,
}

/// Probes the cell `cell` (see the module documentation) from `leads`; `bounds`: every object's
/// box.
pub fn probe_cell(
    rays: &dyn RayCaster,
    cube: &CubeMap,
    cell: &ViewCell,
    leads: &Leads,
    bounds: &[Aabb],
    probing: &RayProbing,
) -> CellProbe {
    let Leads { seen, candidates, region } = *leads;
    let points: Vec<Vec3> = (1..=probing.points).map(|k| halton_point(cell, k)).collect();
    let outside: Vec<usize> = (0..points.len()).into_par_iter().filter(|&i| !is_inside(rays, points[i])).collect();
    let aim = Aim { rays, points: &points, outside: &outside, per_point: probing.rays as usize, nearest: probing.nearest as usize };
    let mut cast = 26 * points.len() as u64;
    // What the cell's own region rays met is seen from the cell: no need to search for it.
    let settled: HashSet<u32> = region.iter().map(|f| f.object).filter(|o| !seen.contains(o)).collect();
    // The unseen objects the candidates' rays meet first, candidates included, each with the
    // point that met it first.
    let mut phases = BakePhases::default();
    let start = Instant::now();
    let (mut found, n) = aim.search(candidates, seen, &settled);
    phases.search = start.elapsed().as_secs_f64();
    cast += n;
    found.sort_unstable();
    found.dedup_by_key(|f| f.0);
    // And what the region's rays met that nothing else found, with their origin.
    let by_region: Vec<(u32, Vec3)> = region
        .iter()
        .map(|f| (f.object, f.origin))
        .filter(|&(o, _)| !seen.contains(&o) && found.binary_search_by_key(&o, |f| f.0).is_err())
        .collect();
    // A found object's DoV is taken at the probe point whose rays meet it most (the likeliest to
    // see most of it), on its footprint there; without any, where it was met: the point whose
    // ray met it on the way to another, or the region ray's origin.
    let objects: Vec<u32> = found.iter().map(|f| f.0).chain(by_region.iter().map(|f| f.0)).collect();
    let start = Instant::now();
    let (hits, n) = aim.hits_by_point(&objects);
    phases.hit_counts = start.elapsed().as_secs_f64();
    cast += n;
    // The place each is measured from: a probe point, or (after them) a region ray's origin.
    let met_at = found.iter().map(|f| (f.1, None)).chain(by_region.iter().map(|f| (points.len(), Some(f.1))));
    let start = Instant::now();
    let measured: Vec<(usize, Vec3, f64, u64)> = objects
        .par_iter()
        .zip(hits.par_iter())
        .zip(met_at.collect::<Vec<_>>().into_par_iter().enumerate())
        .map(|((&object, hits), (k, (seen_from, origin)))| {
            // Most hits; among equals, the earlier (better spread) point.
            let best = (0..points.len()).filter(|&i| hits[i] > 0).min_by_key(|&i| (std::cmp::Reverse(hits[i]), i));
            let (at, p) = match (best, origin) {
                (Some(i), _) => (i, points[i]),
                (None, Some(origin)) => (points.len() + k, origin),
                (None, None) => (seen_from, points[seen_from]),
            };
            let (dov, f) = footprint_dov(rays, cube, p, object, &bounds[object as usize]);
            (at, p, dov, f)
        })
        .collect();
    phases.footprints = start.elapsed().as_secs_f64();
    let mut footprint_rays = 0;
    let mut by_point: HashMap<usize, (Vec3, Vec<(u32, f64)>)> = HashMap::new();
    for (&object, (at, p, dov, footprint)) in objects.iter().zip(measured) {
        footprint_rays += footprint;
        by_point.entry(at).or_insert((p, Vec::new())).1.push((object, dov));
    }
    let mut out: Vec<(Vec3, PointDov)> = by_point
        .into_values()
        .map(|(p, mut objects)| {
            objects.sort_unstable_by_key(|e| e.0);
            (p, PointDov { resolution: cube.resolution(), objects, back_face: 0.0, empty: 0.0 })
        })
        .collect();
    out.sort_by_key(|p| p.1.objects[0].0);
    let (at, points) = out.into_iter().unzip();
    CellProbe { points, at, rays: cast, footprint_rays, phases }
}

/// The objects that the region rays of `cell` ([`RegionRays`] over `sequence`) meet first from
/// the front, each once, with the origin of the first ray that met it, in object order. A ray
/// from inside a closed mesh meets its back faces first and finds nothing.
///
/// The rays are traced sorted by direction (the texels of a 16² cube map), so that one ray
/// after another meets the same walls and the caster's last hit bounds the next, or a run of
/// them goes through the scene together (the CPU backend: one packet, each lane from its own
/// origin); which ray met an object first is still its place in the sequence, so the order
/// changes no result.
pub fn region_finds(caster: &dyn RayCaster, cell: &ViewCell, sequence: &RegionSequence) -> Vec<(u32, Vec3)> {
    region_rays_met(caster, cell, sequence).into_iter().map(|(id, (origin, _), _, _)| (id, origin)).collect()
}

/// An object that region rays met: its id, the first ray (in sequence order) that met it, how
/// many did, and the squares of the cell ([`ViewCell::square_of`]) their origins lie in.
type Met = (u32, (Vec3, Vec3), u32, u64);

/// [`region_finds`] with the whole ray (origin, direction) that met each object first, how
/// many rays met it, and from which squares ([`Met`]).
fn region_rays_met(caster: &dyn RayCaster, cell: &ViewCell, sequence: &RegionSequence) -> Vec<Met> {
    let region = RegionRays::new(cell);
    let rays: Vec<(Vec3, Vec3)> = sequence.points().par_iter().map(|h| region.ray(h)).collect();
    // A counting sort by direction bin (a texel of a 16² cube map), in sequence order within
    // each bin: `sorted[i]` is the ray of sequence place `place[i]`.
    let bins = CubeMap::new(DIRECTION_BINS);
    let bin = |d: Vec3| {
        let (face, row, col) = bins.texel_of_direction(d).unwrap_or_default();
        (face as u32 * DIRECTION_BINS + row) * DIRECTION_BINS + col
    };
    let keys: Vec<u32> = rays.iter().map(|r| bin(r.1)).collect();
    let mut start = vec![0u32; bins.texel_count() + 1];
    for &b in &keys {
        start[b as usize + 1] += 1;
    }
    for b in 1..start.len() {
        start[b] += start[b - 1];
    }
    let (mut sorted, mut place) = (vec![(Vec3::ZERO, Vec3::ZERO); rays.len()], vec![0u32; rays.len()]);
    for (k, (&b, &ray)) in keys.iter().zip(&rays).enumerate() {
        let i = start[b as usize] as usize;
        (sorted[i], place[i]) = (ray, k as u32);
        start[b as usize] += 1;
    }
    // Per object, the first ray in sequence order that met it, that ray, the rays that did and
    // the squares they came from.
    type First = (u32, (Vec3, Vec3), u32, u64);
    let keep_first = |map: &mut HashMap<u32, First>, id: u32, ray: First| {
        let f = map.entry(id).or_insert((ray.0, ray.1, 0, 0));
        f.2 += ray.2;
        f.3 |= ray.3;
        if ray.0 < f.0 {
            (f.0, f.1) = (ray.0, ray.1);
        }
    };
    let first = sorted
        .par_chunks(REGION_CHUNK)
        .zip(place.par_chunks(REGION_CHUNK))
        .map(|(rays, places)| {
            let mut first: HashMap<u32, First> = HashMap::new();
            let ids = caster.first_hits(rays, f32::INFINITY);
            for ((&ray, &k), id) in rays.iter().zip(places).zip(ids) {
                if id != NO_OBJECT && id & BACK_FACE_BIT == 0 {
                    keep_first(&mut first, id, (k, ray, 1, 1 << cell.square_of(ray.0)));
                }
            }
            first
        })
        .reduce(HashMap::new, |mut a, b| {
            for (id, f) in b {
                keep_first(&mut a, id, f);
            }
            a
        });
    let mut met: Vec<Met> = first.into_iter().map(|(id, (_, ray, n, squares))| (id, ray, n, squares)).collect();
    met.sort_unstable_by_key(|m| m.0);
    met
}

/// What region views' ids (`ids`, of `views`: [`DovBackend::region_views`]) show from the front,
/// as [`region_rays_met`] gives it for region rays: each object once, with the ray through the
/// centre of the first texel that showed it and how many texels did, in object order.
fn region_views_met(cell: &ViewCell, views: &RegionViews, ids: &[u32]) -> Vec<Met> {
    let mut first: HashMap<u32, (usize, u32, u64)> = HashMap::new();
    for (k, &id) in ids.iter().enumerate() {
        if id != NO_OBJECT && id & BACK_FACE_BIT == 0 {
            let f = first.entry(id).or_insert((k, 0, 0));
            f.1 += 1;
            f.2 |= 1 << cell.square_of(views.ray(k).0);
        }
    }
    let mut met: Vec<Met> = first.into_iter().map(|(id, (k, n, squares))| (id, views.ray(k), n, squares)).collect();
    met.sort_unstable_by_key(|m| m.0);
    met
}

/// The finds of region sampling (`met`: [`region_rays_met`] or [`region_views_met`]), then rays
/// beside each rare find (met by at most [`BORDER_RARE_HITS`] rays or texels): from the origin
/// of the ray that met an object, rays at [`BORDER_ANGLES`] around its direction, in
/// [`BORDER_AZIMUTHS`] directions, and the same around each object they meet that nothing met
/// before, round after round, until a round finds nothing new or `budget` rays are cast (the
/// adaptive border sampling of guided visibility sampling, Wonka et al. 2006). A gap that one
/// ray went through is seen from that origin, and what lies beside the ray's hit (the rest of a
/// wall behind a doorway, the floor beyond a ledge) is seen through it too, where a ray from
/// anywhere else in the cell rarely passes. Returns the finds in object order and the border
/// rays cast.
fn border_finds(caster: &dyn RayCaster, cell: &ViewCell, met: Vec<Met>, budget: u64) -> (Vec<RegionFind>, u64) {
    // Rays beside an object that many rays met would find what those rays found around it.
    let mut frontier: Vec<(u32, (Vec3, Vec3))> =
        met.iter().filter(|m| m.2 <= BORDER_RARE_HITS).map(|&(id, ray, _, _)| (id, ray)).collect();
    let mut found: HashMap<u32, ((Vec3, Vec3), u64)> =
        met.into_iter().map(|(id, ray, _, squares)| (id, (ray, squares))).collect();
    let fan: Vec<(f32, f32)> = BORDER_ANGLES
        .iter()
        .flat_map(|&a| {
            let a = a.to_radians();
            (0..BORDER_AZIMUTHS).map(move |k| (a, std::f32::consts::TAU * k as f32 / BORDER_AZIMUTHS as f32))
        })
        .collect();
    let mut cast = 0u64;
    while !frontier.is_empty() && cast < budget {
        let room = ((budget - cast) / fan.len() as u64).max(1) as usize;
        frontier.truncate(room);
        // Each find's fan from its ray's origin, traced together (one narrow bundle): each ray
        // (origin, direction) with what it met.
        let rays: Vec<((Vec3, Vec3), u32)> = frontier
            .par_iter()
            .flat_map_iter(|&(_, (origin, d))| {
                let (u, v) = d.any_orthonormal_pair();
                let fan: Vec<(Vec3, f32)> = fan
                    .iter()
                    .map(|&(a, phi)| ((d * a.cos() + (u * phi.cos() + v * phi.sin()) * a.sin()).normalize(), f32::INFINITY))
                    .collect();
                let ids = caster.first_hits_from(origin, &fan);
                fan.into_iter().map(move |(d, _)| (origin, d)).zip(ids)
            })
            .collect();
        let mut next = Vec::new();
        for (ray, id) in rays {
            cast += 1;
            if id == NO_OBJECT || id & BACK_FACE_BIT != 0 {
                continue;
            }
            let square = 1 << cell.square_of(ray.0);
            match found.entry(id) {
                std::collections::hash_map::Entry::Occupied(mut f) => f.get_mut().1 |= square,
                std::collections::hash_map::Entry::Vacant(f) => {
                    f.insert((ray, square));
                    next.push((id, ray));
                }
            }
        }
        frontier = next;
    }
    let mut met: Vec<RegionFind> =
        found.into_iter().map(|(object, ((origin, _), squares))| RegionFind { object, origin, squares }).collect();
    met.sort_unstable_by_key(|m| m.object);
    (met, cast)
}

/// Finds met by at most this many region rays get border rays: seen from little of the cell or
/// through a gap.
const BORDER_RARE_HITS: u32 = 2;

/// Angles (degrees) off a find's ray of the border rays beside it ([`border_finds`]).
const BORDER_ANGLES: [f32; 3] = [0.5, 1.5, 4.0];

/// Border rays per angle, evenly around the find's ray.
const BORDER_AZIMUTHS: u32 = 8;

/// Region rays traced one after another by one thread: enough to share a last hit over many
/// rays, few enough to spread a cell's rays over the threads.
const REGION_CHUNK: usize = 2048;

/// Texels per edge of the cube map whose texels bin region rays by direction: rays in one bin
/// point within about 7° of each other.
const DIRECTION_BINS: u32 = 16;

/// The DoV of `object` from `p` on the cube map's texels whose centre ray enters its box `b`:
/// what a whole cube map at `p` would give it. An object that a probe ray meets but no texel
/// centre does (thinner than a texel from `p`: a pole, a wall seen edge-on) is measured again
/// with [`SUBTEXELS`]² rays per texel, each worth that share of its texel, so that it gets
/// about its true solid angle rather than nothing; if even those miss it, the one-texel floor (it
/// is visible). Returns the DoV and the rays cast.
fn footprint_dov(rays: &dyn RayCaster, cube: &CubeMap, p: Vec3, object: u32, b: &Aabb) -> (f64, u64) {
    let (sum, cast) = footprint_sum(rays, cube, p, object, b, 1);
    if sum > 0.0 {
        return (sum / cube.total_weight(), cast);
    }
    let (fine, more) = footprint_sum(rays, cube, p, object, b, SUBTEXELS);
    let dov = if fine > 0.0 { fine / cube.total_weight() } else { cube.texel_floor() };
    (dov, cast + more)
}

/// Rays per texel edge of a footprint measured again (see [`footprint_dov`]).
const SUBTEXELS: u32 = 2;

/// The solid angle of `object` seen from `p` through the texels of its box's footprint, each
/// traced by `sub`² rays (1: its centre, exactly as [`CubeMap::texel_direction`]), and the rays
/// cast.
fn footprint_sum(rays: &dyn RayCaster, cube: &CubeMap, p: Vec3, object: u32, b: &Aabb, sub: u32) -> (f64, u64) {
    let r = cube.resolution();
    let corners: Vec<Vec3> = (0..8).map(|i| Vec3::new(pick(b, i, 0), pick(b, i, 1), pick(b, i, 2)) - p).collect();
    let texel = 2.0 / r as f64;
    let offsets: Vec<f64> = (0..sub).map(|k| texel * ((k as f64 + 0.5) / sub as f64 - 0.5)).collect();
    let share = 1.0 / (sub * sub) as f64;
    // Each ray that enters the box, with its texel's weight; traced together from `p`.
    let (mut footprint, mut weights) = (Vec::new(), Vec::new());
    for face in 0..FACE_COUNT {
        let basis = face_basis(face);
        let Some((cols, rows)) = face_rect(&corners, basis, r) else { continue };
        for row in rows {
            for col in cols.clone() {
                let (u, v) = cube.texel_uv(row, col);
                for dv in &offsets {
                    for du in &offsets {
                        let d = uv_direction(face, u + du, v - dv);
                        let Some(exit) = box_exit(p, d, b) else { continue };
                        // Nothing beyond the box can be the object.
                        footprint.push((d, exit * TARGET_REACH));
                        weights.push(cube.weight(row, col) * share);
                    }
                }
            }
        }
    }
    let ids = rays.first_hits_from(p, &footprint);
    let sum = ids.iter().zip(&weights).filter(|(id, _)| **id & !BACK_FACE_BIT == object).map(|(_, w)| w).sum();
    (sum, footprint.len() as u64)
}

/// Coordinate `axis` of box corner `i` (bit `axis` of `i` picks max).
fn pick(b: &Aabb, i: usize, axis: usize) -> f32 {
    if i >> axis & 1 == 1 { b.max[axis] } else { b.min[axis] }
}

/// The columns and rows of face `basis` that a box with corners `corners` (relative to the eye,
/// in [`pick`]'s order) can cover, or `None` when it lies wholly behind the face. The part of the
/// box in front of the face's plane projects inside the hull of its corners there and of the
/// points where its edges cross the plane (just in front of it, where they project far out).
fn face_rect(
    corners: &[Vec3],
    basis: crate::dov::cubemap::FaceBasis,
    r: u32,
) -> Option<(std::ops::Range<u32>, std::ops::Range<u32>)> {
    const IN_FRONT: f32 = 1e-6;
    let z: Vec<f32> = corners.iter().map(|c| c.dot(basis.forward)).collect();
    let mut points: Vec<Vec3> = (0..8).filter(|&i| z[i] > IN_FRONT).map(|i| corners[i]).collect();
    if points.is_empty() {
        return None;
    }
    // The 12 edges join corners that differ in one bit.
    for i in 0..8 {
        for axis in 0..3 {
            let j = i | 1 << axis;
            if j != i && (z[i] > IN_FRONT) != (z[j] > IN_FRONT) {
                let s = (IN_FRONT - z[i]) / (z[j] - z[i]);
                points.push(corners[i] + s * (corners[j] - corners[i]));
            }
        }
    }
    let (mut u0, mut u1, mut v0, mut v1) = (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY);
    for c in &points {
        let z = c.dot(basis.forward).max(IN_FRONT);
        let (u, v) = (c.dot(basis.right) / z, c.dot(basis.up) / z);
        (u0, u1, v0, v1) = (u0.min(u), u1.max(u), v0.min(v), v1.max(v));
    }
    if u1 < -1.0 || u0 > 1.0 || v1 < -1.0 || v0 > 1.0 {
        return None;
    }
    // Texel centres: u = 2(col + ½)/R − 1, v = 1 − 2(row + ½)/R; one texel of slack each side.
    let rf = r as f32;
    let col = |u: f32| ((u + 1.0) * 0.5 * rf).clamp(0.0, rf);
    let row = |v: f32| ((1.0 - v) * 0.5 * rf).clamp(0.0, rf);
    let cols = (col(u0) as u32).saturating_sub(1)..(col(u1) as u32 + 1).min(r);
    let rows = (row(v1) as u32).saturating_sub(1)..(row(v0) as u32 + 1).min(r);
    Some((cols, rows))
}

/// Where the ray from `p` along `d` (t ≥ 0) leaves box `b`, slightly grown against rounding, if
/// it enters it at all.
fn box_exit(p: Vec3, d: Vec3, b: &Aabb) -> Option<f32> {
    let pad = 1e-4 * b.extent().max_element().max(1e-3);
    let inv = d.recip();
    let t0 = (b.min - Vec3::splat(pad) - p) * inv;
    let t1 = (b.max + Vec3::splat(pad) - p) * inv;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element();
    (near <= far).then_some(far)
}

/// Where lattice cells are sampled whole and refined into their view cells
/// ([`ViewGrid::refines_lattice_cells`]), each view cell casts this share of the region rays:
/// half, so that a lattice cell's four quarters cast twice a whole cell's. On aggressor in
/// quarters a quarter of them missed 3.1e-6 of a view on average, a half 1.0e-6 and all of them
/// 1.1e-6 for 9 % more build time (decision 130).
const REFINED_REGION_SHARE: u32 = 2;

/// How many rings of neighbouring cells' region finds are a cell's probe candidates.
pub const REGION_RING: u32 = 8;

/// How many rings of neighbouring cells' corners give ray probing its candidates: on the audit
/// scene two rings left 33 % fewer pairs unfound than one, three rings 16 % fewer again at 30 %
/// more rays (docs/journal/dov-sampling.md, §2).
pub const PROBE_CANDIDATE_RING: u32 = 2;

/// The rings of neighbouring corners whose sight makes candidates in a grid of view cells made
/// where viewers stand ([`ViewGrid::where_viewers_stand`]): one. Two rings of 2 m cells reach
/// 4 m into the next rooms and along other corridors, whose objects are hidden from the cell and
/// cost every one of their aimed rays: on four game levels and a house the second ring found
/// nothing that the misses show (the same wrong share to every digit) and took 12–19 % of the
/// build (decision 129).
pub const ROOM_CANDIDATE_RING: u32 = 1;

/// The rings of neighbouring corners whose sight makes candidates in `grid`.
fn candidate_ring(grid: &ViewGrid) -> u32 {
    if grid.where_viewers_stand() { ROOM_CANDIDATE_RING } else { PROBE_CANDIDATE_RING }
}

/// Ray probing, with the region rays of a shard's cells and their neighbours: what a cell's
/// rays meet it sees, and its neighbours probe for (an object seen from part of a cell is the
/// likeliest to be seen from part of the next, where that cell's own rays may have missed it).
pub struct Probe {
    probing: RayProbing,
    /// What each cell's region rays met ([`region_finds`]), by cell id (by lattice cell where the
    /// precompute refines, [`ViewGrid::refines_lattice_cells`]).
    region: HashMap<usize, Vec<RegionFind>>,
    /// The cell sampled last: where its probe findings were measured from, and what each saw.
    placed: Vec<(Vec3, Vec<u32>)>,
}

impl Probe {
    pub fn new(probing: RayProbing) -> Self {
        Probe { probing, region: HashMap::new(), placed: Vec::new() }
    }

    /// The objects that the region rays of the cells within [`REGION_RING`] of `cell` (itself
    /// left out) met, which no point of `cell` saw and which are not candidates already, each with
    /// the origins of the rays that met it: nearest ring first (by object within a ring), as many
    /// objects as probing them would cost the cell's own region rays at most.
    fn region_candidates(
        &self,
        cell: &CellSite,
        seen: &HashSet<u32>,
        candidates: &BTreeMap<u32, Vec<Vec3>>,
    ) -> BTreeMap<u32, Vec<Vec3>> {
        let p = self.probing;
        let cap = (p.region / (p.points * p.rays).max(1)) as usize;
        let mut by_ring: Vec<Vec<usize>> = vec![Vec::new(); REGION_RING as usize + 1];
        for n in cell.grid.neighbourhood_view_cells(cell.coords, REGION_RING) {
            let c = cell.grid.cell_coords(n);
            by_ring[(0..3).map(|a| c[a].abs_diff(cell.coords[a])).max().unwrap_or(0) as usize].push(n);
        }
        let mut taken: BTreeMap<u32, Vec<Vec3>> = BTreeMap::new();
        // The cell itself is ring 0.
        for ring in &by_ring[1..] {
            if taken.len() == cap {
                break;
            }
            let mut finds: Vec<(u32, Vec3)> = ring
                .iter()
                .flat_map(|n| self.region.get(n).into_iter().flatten().map(|f| (f.object, f.origin)))
                .filter(|(o, _)| !seen.contains(o) && !candidates.contains_key(o))
                .collect();
            finds.sort_by_key(|f| f.0);
            for (o, origin) in finds {
                if taken.len() < cap || taken.contains_key(&o) {
                    taken.entry(o).or_default().push(origin);
                }
            }
        }
        taken
    }
}

/// What the neighbouring corners within [`candidate_ring`] of `cell` see (those outside
/// geometry), each object with where it was seen from.
fn corner_candidates(cell: &CellSite) -> BTreeMap<u32, Vec<Vec3>> {
    let mut candidates: BTreeMap<u32, Vec<Vec3>> = BTreeMap::new();
    // A corner within the ring lies at most that many cells from the cell's box along every
    // axis (a hundredth more for rounding).
    let reach = cell.bounds.extent() * (candidate_ring(cell.grid) as f32 + 0.01);
    for (corner, &at) in cell.nearby.iter().zip(cell.nearby_at) {
        let gap = (cell.bounds.min - at).max(at - cell.bounds.max);
        if gap.cmpgt(reach).any() || crate::dov::sampling::is_inside(corner) {
            continue;
        }
        for &(o, _) in &corner.objects {
            candidates.entry(o).or_default().push(at);
        }
    }
    candidates
}

impl CellSampler for Probe {
    fn corner_ring(&self) -> u32 {
        PROBE_CANDIDATE_RING
    }

    fn casts_rays(&self) -> bool {
        true
    }

    fn prepare(&mut self, backend: &mut dyn DovBackend, grid: &ViewGrid, cells: &[usize], tally: &mut Tally) -> Result<()> {
        if backend.ray_caster().is_none() {
            return Err(Error::bad_param(
                Param::Samples,
                format!("{} casts single rays: the {} backend has none (use the cpu backend)", self.probing, backend.name()),
            ));
        }
        if self.probing.region == 0 {
            return Ok(());
        }
        // The neighbours that are view cells (rays from inside a solid would find what no viewer
        // sees). Where the precompute refines, by lattice cell: each of its view cells casts its
        // share of the rays, and the lattice cell keeps what any of them met and from where.
        let split = grid.refines_lattice_cells();
        let mut ids: Vec<usize> = cells
            .iter()
            .flat_map(|&id| grid.neighbourhood_view_cells(grid.cell_coords(id), REGION_RING))
            .map(|id| if split { grid.cell_id(grid.cell_coords(id)) } else { id })
            .collect();
        ids.sort_unstable();
        ids.dedup();
        let count = if split { self.probing.region / REFINED_REGION_SHARE } else { self.probing.region };
        let sequence = RegionSequence::new(count);
        let budget = u64::from(count) / 2;
        for id in ids {
            let cells: Vec<ViewCell> = match split {
                true => grid.view_cells_of(id).map(|v| grid.view_cell(v)).collect(),
                false => vec![grid.view_cell(id)],
            };
            let mut union: BTreeMap<u32, (Vec3, u64)> = BTreeMap::new();
            for cell in cells {
                // Drawn where the backend draws region views (the GPU), else cast.
                let start = Instant::now();
                let met = match backend.region_views(&cell, count) {
                    Some(drawn) => {
                        let (views, ids) = drawn?;
                        tally.region_views += views.views().len() as u64;
                        region_views_met(&cell, &views, &ids)
                    }
                    None => {
                        tally.probe_rays += u64::from(count);
                        region_rays_met(backend.ray_caster().expect("checked above"), &cell, &sequence)
                    }
                };
                tally.phases.region_rays += start.elapsed().as_secs_f64();
                let start = Instant::now();
                let (finds, border) = border_finds(backend.ray_caster().expect("checked above"), &cell, met, budget);
                tally.phases.border_rays += start.elapsed().as_secs_f64();
                tally.probe_rays += border;
                for f in finds {
                    union.entry(f.object).or_insert((f.origin, 0)).1 |= f.squares;
                }
            }
            let finds = union.into_iter().map(|(object, (origin, squares))| RegionFind { object, origin, squares });
            self.region.insert(id, finds.collect());
        }
        Ok(())
    }

    fn sample(&mut self, backend: &mut dyn DovBackend, cell: &CellSite, points: &mut Vec<PointDov>, tally: &mut Tally) -> Result<()> {
        let caster = backend.ray_caster().expect("prepare refuses a backend without a ray caster");
        let seen = seen_by(cell.corners.iter().copied().chain(points.iter()));
        // Candidates, each with where nearby it was seen: what the neighbouring cells' corners
        // see, what meets the cell, and what their region rays met.
        let mut candidates = corner_candidates(cell);
        for o in (0..cell.object_bounds.len() as u32).filter(|&o| cell.object_bounds[o as usize].intersects(&cell.bounds)) {
            candidates.entry(o).or_default();
        }
        if self.probing.region > 0 {
            let nearby = self.region_candidates(cell, &seen, &candidates);
            candidates.extend(nearby);
        }
        // probe_cell skips the seen ones.
        let candidates: Vec<Candidate> =
            candidates.into_iter().map(|(object, seen_from)| Candidate { object, seen_from }).collect();
        let own = self.region.get(&cell.id).map_or(&[][..], Vec::as_slice);
        let leads = Leads { seen: &seen, candidates: &candidates, region: own };
        let probe = probe_cell(caster, cell.cube, &cell.view_cell(), &leads, cell.object_bounds, &self.probing);
        tally.probe_rays += probe.rays;
        tally.footprint_rays += probe.footprint_rays;
        tally.phases.add(&probe.phases);
        self.placed = probe.at.iter().zip(&probe.points).map(|(&p, v)| (p, v.objects.iter().map(|e| e.0).collect())).collect();
        points.extend(probe.points);
        Ok(())
    }

    fn refine(
        &mut self,
        backend: &mut dyn DovBackend,
        cell: &CellSite,
        places: u64,
        seen: &HashSet<u32>,
        candidates: &[u32],
        tally: &mut Tally,
    ) -> Result<Option<HashSet<u32>>> {
        let start = Instant::now();
        let caster = backend.ray_caster().expect("prepare refuses a backend without a ray caster");
        let part = ViewCell { bounds: cell.bounds, places };
        // Seen from these squares and those around them: what the region rays cast from them
        // met, what probing measured from them; the rest of what the whole cell sees is searched
        // for from points of their own, as a cell searches for its candidates. The squares
        // around count because a viewer on the view cell's border sees what is seen just
        // across it, and views change continuously.
        let around = places_around(places, cell.places);
        let here = |p: Vec3| around >> part.square_of(p) & 1 == 1;
        let mut found = seen.clone();
        for (p, objects) in &self.placed {
            if here(*p) {
                found.extend(objects);
            }
        }
        if let Some(finds) = self.region.get(&cell.id) {
            found.extend(finds.iter().filter(|f| f.squares & around != 0).map(|f| f.object));
        }
        // And what the region rays of the lattice cells beside met from the squares just across
        // the border, where nothing stands between the two squares (a wall on the border).
        for (n, pairs) in cell.grid.squares_across(cell.coords, places) {
            let Some(finds) = self.region.get(&n) else { continue };
            let coords = cell.grid.cell_coords(n);
            let rays: Vec<(Vec3, Vec3)> = pairs
                .iter()
                .map(|&(their, own)| {
                    let from = cell.grid.square_centre(cell.coords, own);
                    (from, cell.grid.square_centre(coords, their) - from)
                })
                .collect();
            let clear = caster.first_hits(&rays, 1.0);
            tally.probe_rays += rays.len() as u64;
            let across = pairs.iter().zip(clear).filter(|(_, id)| *id == NO_OBJECT).fold(0u64, |m, (p, _)| m | 1 << p.0);
            found.extend(finds.iter().filter(|f| f.squares & across != 0).map(|f| f.object));
        }
        let left: Vec<Candidate> = candidates
            .iter()
            .filter(|o| !found.contains(o))
            .map(|&object| Candidate { object, seen_from: Vec::new() })
            .collect();
        if !left.is_empty() {
            let points: Vec<Vec3> = (1..=self.probing.points).map(|k| halton_point(&part, k)).collect();
            let outside: Vec<usize> = (0..points.len()).into_par_iter().filter(|&i| !is_inside(caster, points[i])).collect();
            let aim = Aim {
                rays: caster,
                points: &points,
                outside: &outside,
                per_point: self.probing.rays as usize,
                nearest: self.probing.nearest as usize,
            };
            let (met, cast) = aim.search(&left, &found, &HashSet::new());
            tally.probe_rays += cast + 26 * points.len() as u64;
            found.extend(met.into_iter().map(|m| m.0));
        }
        tally.phases.refine += start.elapsed().as_secs_f64();
        Ok(Some(found))
    }

    fn found_from(&self, cell: usize) -> Option<Vec<u32>> {
        self.region.get(&cell).map(|finds| finds.iter().map(|f| f.object).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dov::CpuBackend;
    use crate::scene::Scene;

    /// A few boxes around the origin, some straddling cube faces.
    fn boxes() -> Scene {
        let mut s = Scene::default();
        s.add_box("front", Vec3::new(-1.0, -0.5, 4.0), Vec3::new(1.5, 1.0, 4.5));
        s.add_box("corner", Vec3::new(3.0, -1.0, 3.0), Vec3::new(5.0, 2.0, 5.0));
        s.add_box("below", Vec3::new(-6.0, -3.0, -6.0), Vec3::new(6.0, -2.0, 6.0));
        s.add_box("far", Vec3::new(-20.0, 3.0, -30.0), Vec3::new(-19.0, 4.0, -29.5));
        s
    }

    /// Traced in direction order, the region rays find what tracing them in sequence order finds:
    /// each object hit from the front, with the origin of the first ray (in sequence) to hit it.
    #[test]
    fn region_finds_are_the_sequence_order_scan() {
        let scene = boxes();
        let cpu = CpuBackend::new(&scene, 16).unwrap();
        let sequence = RegionSequence::new(3000);
        let half = (0..8).fold(0u64, |m, z| m | 0x0f << (8 * z));
        for cell in [
            ViewCell::whole(Aabb::new(Vec3::new(-0.5, -0.5, -0.5), Vec3::new(0.5, 0.5, 0.5))),
            ViewCell::whole(Aabb::new(Vec3::ZERO, Vec3::ONE)),
            ViewCell { bounds: Aabb::new(Vec3::ZERO, Vec3::ONE), places: half },
        ] {
            let region = RegionRays::new(&cell);
            let mut expected: Vec<(u32, Vec3)> = Vec::new();
            for h in sequence.points() {
                let (origin, dir) = region.ray(h);
                let id = cpu.first_hit(origin, dir, f32::INFINITY);
                if id != NO_OBJECT && id & BACK_FACE_BIT == 0 && !expected.iter().any(|e| e.0 == id) {
                    expected.push((id, origin));
                }
            }
            expected.sort_by_key(|e| e.0);
            assert!(expected.len() >= 3, "{} objects found", expected.len());
            assert_eq!(region_finds(&cpu, &cell, &sequence), expected);
        }
    }

    /// Corners two cells away make candidates on an open grid and not on cells made where
    /// viewers stand (rooms: [`ROOM_CANDIDATE_RING`]); those one cell away do on both, and a
    /// corner inside geometry never does.
    #[test]
    fn rooms_take_candidates_from_one_ring_of_corners() {
        let open = ViewGrid::new(Aabb::new(Vec3::ZERO, Vec3::new(10.0, 1.0, 10.0)), [5, 1, 5]);
        let rooms = ViewGrid {
            present: Some(crate::grid::CellSet::from_ids((0..25).collect())),
            places: Some(vec![crate::grid::ALL_PLACES; 25]),
            ..open.clone()
        };
        assert!(rooms.where_viewers_stand() && !open.where_viewers_stand());
        let sees = |objects: &[u32], back_face: f64| PointDov {
            resolution: 16,
            objects: objects.iter().map(|&o| (o, 0.01)).collect(),
            back_face,
            empty: 0.0,
        };
        // The middle cell (4..6 along x and z); corners at one, two and one cell away (inside).
        let nearby = [sees(&[1], 0.0), sees(&[2], 0.0), sees(&[3], 0.9)];
        let nearby: Vec<&PointDov> = nearby.iter().collect();
        let nearby_at = [Vec3::new(2.0, 0.0, 4.0), Vec3::new(0.0, 1.0, 8.0), Vec3::new(8.0, 0.0, 6.0)];
        let cube = CubeMap::new(16);
        let site = |grid| CellSite {
            id: 12,
            coords: [2, 0, 2],
            bounds: Aabb::new(Vec3::new(4.0, 0.0, 4.0), Vec3::new(6.0, 1.0, 6.0)),
            places: crate::grid::ALL_PLACES,
            grid,
            corners: &[],
            nearby: &nearby,
            nearby_at: &nearby_at,
            object_bounds: &[],
            cube: &cube,
        };
        let objects = |grid| corner_candidates(&site(grid)).into_keys().collect::<Vec<u32>>();
        assert_eq!(objects(&open), [1, 2]);
        assert_eq!(objects(&rooms), [1]);
    }

    /// A view cell refined from its lattice cell takes what the region rays met from the squares
    /// around its own: beside it in its lattice cell, and across the lattice cell's border where
    /// nothing stands between the two squares; not from squares farther off.
    #[test]
    fn a_view_cell_takes_what_was_seen_from_the_squares_around_it() {
        use crate::grid::{ALL_PLACES, CellSet, QUARTERS};
        // 5 × 1 × 5 lattice cells of 2 m from (100, 0, 100), viewers everywhere.
        let grid = ViewGrid {
            present: Some(CellSet::from_ids((0..25).collect())),
            places: Some(vec![ALL_PLACES; 25]),
            ..ViewGrid::new(Aabb::new(Vec3::new(100.0, 0.0, 100.0), Vec3::new(110.0, 1.0, 110.0)), [5, 1, 5])
        };
        let (id, coords, beside) = (12, [2, 0, 2], 13);
        let square = |x: u32, z: u32| 1u64 << (z * 8 + x);
        let find = |object: u32, squares: u64| RegionFind { object, origin: Vec3::ZERO, squares };
        let cube = CubeMap::new(16);
        let site = |grid| CellSite {
            id,
            coords,
            bounds: Aabb::new(Vec3::new(104.0, 0.0, 104.0), Vec3::new(106.0, 1.0, 106.0)),
            places: ALL_PLACES,
            grid,
            corners: &[],
            nearby: &[],
            nearby_at: &[],
            object_bounds: &[],
            cube: &cube,
        };
        let refined = |scene: &Scene| {
            let mut probe = Probe::new(RayProbing::REGION);
            // Object 1 met from the square beside the quarter (x 3), 2 from one farther off (x 1),
            // 3 from the quarter itself; 4 from the cell beside along +x, just across (its x 0),
            // 5 from that cell's far side (its x 7).
            probe.region.insert(id, vec![find(1, square(3, 2)), find(2, square(1, 2)), find(3, square(5, 1))]);
            probe.region.insert(beside, vec![find(4, square(0, 3)), find(5, square(7, 3))]);
            let mut cpu = CpuBackend::new(scene, 16).unwrap();
            let mut tally = Tally::new(0, &crate::progress::Quiet);
            let found = probe.refine(&mut cpu, &site(&grid), QUARTERS[1], &HashSet::new(), &[], &mut tally).unwrap().unwrap();
            let mut found: Vec<u32> = found.into_iter().collect();
            found.sort_unstable();
            found
        };
        assert_eq!(refined(&boxes()), [1, 3, 4]);
        // A wall on the border between the two lattice cells: nothing from across it.
        let mut walled = boxes();
        walled.add_box("wall", Vec3::new(105.95, 0.0, 104.0), Vec3::new(106.05, 1.0, 106.0));
        assert_eq!(refined(&walled), [1, 3]);
    }

    /// A candidate seen nearby is searched for from the NEAREST points outside geometry nearest
    /// the places that saw it, nearest first; one seen from nowhere nearby (its box meets the
    /// cell) from every point outside geometry, in point order.
    #[test]
    fn candidates_are_searched_for_from_the_points_nearest_where_they_were_seen() {
        let cpu = CpuBackend::new(&boxes(), 16).unwrap();
        let points: Vec<Vec3> = (0..8).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
        // Point 4 lies inside geometry.
        let outside = [0, 1, 2, 3, 5, 6, 7];
        let aim = |nearest| Aim { rays: &cpu, points: &points, outside: &outside, per_point: 4, nearest };
        assert_eq!(aim(3).guided_points(&[Vec3::new(6.2, 0.0, 0.0)]), [6, 7, 5]);
        // Two places: the nearer of the two counts; among equals, point order.
        assert_eq!(aim(3).guided_points(&[Vec3::ZERO, Vec3::new(7.0, 0.0, 0.0)]), [0, 7, 1]);
        assert_eq!(aim(8).guided_points(&[Vec3::new(4.0, 0.0, 0.0)]), [3, 5, 2, 6, 1, 7, 0]);
        for nearest in [1, 3, 8] {
            assert_eq!(aim(nearest).guided_points(&[]), outside);
        }
    }

    #[test]
    fn a_footprint_gives_the_dov_a_whole_cube_map_gives() {
        let scene = boxes();
        let mut cpu = CpuBackend::new(&scene, 32).unwrap();
        let bounds = scene.all_object_bounds();
        for p in [Vec3::ZERO, Vec3::new(0.3, 0.2, -0.7)] {
            let whole = cpu.measure(p).unwrap();
            let cube = cpu.cube_map().clone();
            for (o, b) in bounds.iter().enumerate() {
                let (dov, _) = footprint_dov(&cpu, &cube, p, o as u32, b);
                match whole.objects.iter().find(|e| e.0 == o as u32) {
                    Some(&(_, expected)) => {
                        assert!((dov - expected).abs() < 1e-12, "object {o} from {p}: {dov} vs {expected}")
                    }
                    // The far box falls between texel centres from the origin: measured finer.
                    None => assert!(dov > 0.0 && dov < 2.0 * cube.texel_floor(), "object {o} from {p}: {dov}"),
                }
            }
        }
    }

    /// Rectangle of w × h centred on the axis at distance d: 4·asin(sin α · sin β).
    fn rectangle_dov(w: f64, h: f64, d: f64) -> f64 {
        4.0 * ((w / 2.0 / d).atan().sin() * (h / 2.0 / d).atan().sin()).asin() / (4.0 * std::f64::consts::PI)
    }

    #[test]
    fn a_pole_between_texel_centres_gets_about_its_solid_angle() {
        // R = 32: texel centres at x = ±0.3125 at distance 10 on face +Z; the pole (0.2 wide,
        // a third of a texel) lies between them, so the whole cube map misses it.
        let mut scene = Scene::default();
        scene.add_box("pole", Vec3::new(-0.1, -1.0, 10.0), Vec3::new(0.1, 1.0, 10.05));
        let mut cpu = CpuBackend::new(&scene, 32).unwrap();
        assert!(cpu.measure(Vec3::ZERO).unwrap().objects.is_empty());
        let cube = cpu.cube_map().clone();
        let (dov, _) = footprint_dov(&cpu, &cube, Vec3::ZERO, 0, &scene.object_bounds(0));
        let truth = rectangle_dov(0.2, 2.0, 10.0);
        // Sub-texel columns are 1/SUBTEXELS of a texel apart: the estimate is within one of them.
        let column = rectangle_dov(0.625 / SUBTEXELS as f64, 2.0, 10.0);
        assert!((dov - truth).abs() <= column, "pole: {dov} vs {truth} (± {column})");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Whatever the boxes and the point (boxes straddling cube faces, behind the point, around
        /// it), an object's footprint DoV is exactly what the whole cube map gives it.
        #[test]
        fn footprints_equal_whole_cube_maps(
            boxes in proptest::collection::vec(([-8.0f32..8.0, -8.0f32..8.0, -8.0f32..8.0], [0.05f32..6.0, 0.05f32..6.0, 0.05f32..6.0]), 1..6),
            eye in [-2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0],
        ) {
            let mut scene = Scene::default();
            for (i, (min, size)) in boxes.iter().enumerate() {
                let min = Vec3::from(*min);
                scene.add_box(&format!("b{i}"), min, min + Vec3::from(*size));
            }
            let mut cpu = CpuBackend::new(&scene, 16).unwrap();
            let p = Vec3::from(eye);
            let whole = cpu.measure(p).unwrap();
            let cube = cpu.cube_map().clone();
            for &(o, expected) in &whole.objects {
                let (dov, _) = footprint_dov(&cpu, &cube, p, o, &scene.object_bounds(o as usize));
                proptest::prop_assert!((dov - expected).abs() < 1e-12, "object {} from {}: {} vs {}", o, p, dov, expected);
            }
        }
    }
}
