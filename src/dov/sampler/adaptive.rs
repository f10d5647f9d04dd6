//! Adaptive from-region sampling: spend sample points in a cell where new objects appear
//! (guided visibility sampling, Wonka et al. 2006; adaptive global visibility sampling, Bittner
//! et al. 2009), instead of a fixed set of interior points.
//!
//! The cell's 8 corners are measured anyway (shared with the neighbours). Then, in rounds:
//! - round 0: `seeds` well-spread Halton points of the cell;
//! - every point that sees an object no earlier point of the cell saw (a *finder*) gets children:
//!   the points a step away from it along each long axis of the cell, the step halving with each
//!   generation (¼, ⅛, … of the cell), because an object seen from part of a cell only (through a
//!   gap, past a corner) is seen from a neighbourhood of the finder and, past its border, not;
//! - every round also takes the next Halton point, so regions far from all finders keep being
//!   explored;
//! - the rounds stop when one reveals nothing new and every *candidate* has been seen (the
//!   stopping rule), or when the cell has measured `budget` interior points. Candidates are the
//!   objects that the neighbouring cells' corners see (measured anyway): views change
//!   continuously, so an object seen just outside the cell is the likeliest to be seen from part
//!   of it; while one is unseen, the cell keeps exploring with Halton points.
//!
//! It works through [`DovBackend::measure`] only, so both backends use it. The cell's DoV stays
//! the max over all measured points ([`crate::dov::precompute::cell_dov`]).

use std::collections::HashSet;

use glam::Vec3;

use super::{CellSampler, CellSite, Tally};
use crate::dov::sampling::{halton3, is_inside, seen_by};
use crate::dov::{DovBackend, PointDov};
use crate::error::Result;
use crate::format::sampling::AdaptiveSampling;
use crate::grid::ViewCell;

/// The axes along which a cell's view changes most: those at least half as long as its longest
/// (a flat 5 × 0.5 × 5 cell refines in x and z only).
fn long_axes(extent: Vec3) -> Vec<usize> {
    let longest = extent.max_element();
    (0..3).filter(|&a| extent[a] >= 0.5 * longest).collect()
}

/// Measures the adaptive interior points of the cell `cell` (see the module documentation).
/// `known` are the points measured for the cell already (its corners): what they see is not new;
/// `candidates` keep the cell sampling while one of them is unseen (see the module
/// documentation). Points inside geometry ([`crate::dov::precompute::PrecomputeOptions::skip_inside_points`]) reveal
/// nothing. `measured` is called after each measurement. Returns the measurements, at most
/// `budget`, in the order taken.
pub fn sample_cell(
    backend: &mut dyn DovBackend,
    cell: &ViewCell,
    known: &[&PointDov],
    candidates: &HashSet<u32>,
    sampling: &AdaptiveSampling,
    measured: &mut dyn FnMut(),
) -> Result<Vec<PointDov>> {
    let axes = long_axes(cell.bounds.extent());
    let budget = sampling.budget as usize;
    let mut seen: HashSet<u32> = seen_by(known.iter().copied());
    // Cell-relative positions in [0, 1]³ already taken (the corners included), so that children
    // of neighbouring finders do not measure one place twice.
    let mut placed: Vec<Vec3> =
        (0..8).map(|i| Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32)).collect();
    let mut halton = 0;
    let mut next_halton = |placed: &mut Vec<Vec3>| {
        halton += 1;
        let u = halton3(halton);
        placed.push(u);
        (u, 0u32)
    };
    let mut round: Vec<(Vec3, u32)> = (0..sampling.seeds).map(|_| next_halton(&mut placed)).collect();
    let mut out = Vec::new();
    while !round.is_empty() && out.len() < budget {
        let mut next = Vec::new();
        for (u, generation) in round {
            if out.len() >= budget {
                break;
            }
            let d = backend.measure(cell.point(u))?;
            measured();
            let before = seen.len();
            if !is_inside(&d) {
                seen.extend(d.objects.iter().map(|e| e.0));
            }
            if seen.len() > before {
                let step = 0.5f32.powi(generation as i32 + 2);
                for &a in &axes {
                    for sign in [-1.0, 1.0] {
                        let mut child = u;
                        child[a] = (child[a] + sign * step).clamp(0.0, 1.0);
                        if placed.iter().all(|q| q.distance(child) > 0.25 * step) {
                            placed.push(child);
                            next.push((child, generation + 1));
                        }
                    }
                }
            }
            out.push(d);
        }
        // The stopping rule: a round that revealed nothing new ends the cell, unless a candidate
        // is still unseen.
        if next.is_empty() && candidates.iter().all(|c| seen.contains(c)) {
            break;
        }
        next.push(next_halton(&mut placed));
        round = next;
    }
    Ok(out)
}

/// The adaptive sampler: [`sample_cell`], its candidates the objects the neighbouring cells'
/// corners see.
pub struct Adaptive(pub AdaptiveSampling);

impl CellSampler for Adaptive {
    fn corner_ring(&self) -> u32 {
        1
    }

    /// Its seeds: how many more it takes is known only when it stops.
    fn planned_points(&self) -> u32 {
        self.0.seeds
    }

    fn sample(&mut self, backend: &mut dyn DovBackend, cell: &CellSite, points: &mut Vec<PointDov>, tally: &mut Tally) -> Result<()> {
        let start = std::time::Instant::now();
        let known: Vec<&PointDov> = cell.corners.iter().copied().chain(points.iter()).collect();
        let candidates = seen_by(cell.nearby.iter().copied());
        let planned = self.0.seeds as usize;
        let mut taken = 0;
        let extra = sample_cell(backend, &cell.view_cell(), &known, &candidates, &self.0, &mut || {
            taken += 1;
            tally.measured(taken > planned);
        })?;
        points.extend(extra);
        tally.phases.points += start.elapsed().as_secs_f64();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dov::{CubeMap, IdCube};

    /// A backend whose view is a function of the point: object `i` is seen (DoV 0.01) wherever
    /// `sees(p, i)`. Counts its measurements.
    struct Fake<F: Fn(Vec3, u32) -> bool> {
        sees: F,
        objects: u32,
        cube: CubeMap,
        calls: usize,
    }

    impl<F: Fn(Vec3, u32) -> bool> Fake<F> {
        fn new(objects: u32, sees: F) -> Self {
            Self { sees, objects, cube: CubeMap::new(2), calls: 0 }
        }
    }

    impl<F: Fn(Vec3, u32) -> bool> DovBackend for Fake<F> {
        fn name(&self) -> String {
            "fake".into()
        }
        fn resolution(&self) -> u32 {
            2
        }
        fn cube_map(&self) -> &CubeMap {
            &self.cube
        }
        fn render_ids(&mut self, _: Vec3, _: &mut IdCube) -> Result<()> {
            unreachable!("the sampler only measures")
        }
        fn measure(&mut self, p: Vec3) -> Result<PointDov> {
            self.calls += 1;
            let objects = (0..self.objects).filter(|&i| (self.sees)(p, i)).map(|i| (i, 0.01)).collect();
            Ok(PointDov { resolution: 2, objects, back_face: 0.0, empty: 0.5 })
        }
    }

    use crate::geom::Aabb;

    fn cell() -> ViewCell {
        ViewCell::whole(Aabb::new(Vec3::ZERO, Vec3::new(4.0, 0.5, 4.0)))
    }

    fn corners(b: &mut dyn DovBackend) -> Vec<PointDov> {
        let c = cell().bounds;
        (0..8)
            .map(|i| {
                let pick = |bit: usize, a: usize| if i >> bit & 1 == 1 { c.max[a] } else { c.min[a] };
                b.measure(Vec3::new(pick(0, 0), pick(1, 1), pick(2, 2))).unwrap()
            })
            .collect()
    }

    fn run(b: &mut dyn DovBackend, sampling: AdaptiveSampling) -> (Vec<PointDov>, usize) {
        run_with(b, sampling, &HashSet::new())
    }

    fn run_with(
        b: &mut dyn DovBackend,
        sampling: AdaptiveSampling,
        candidates: &HashSet<u32>,
    ) -> (Vec<PointDov>, usize) {
        let known = corners(b);
        let refs: Vec<&PointDov> = known.iter().collect();
        let mut count = 0;
        let out = sample_cell(b, &cell(), &refs, candidates, &sampling, &mut || count += 1).unwrap();
        assert_eq!(out.len(), count);
        (out, count)
    }

    #[test]
    fn stops_after_a_round_that_finds_nothing_new() {
        // Every point sees the same object: the seeds reveal nothing beyond the corners.
        let mut b = Fake::new(1, |_, _| true);
        let (_, n) = run(&mut b, AdaptiveSampling::new(3, 16).unwrap());
        assert_eq!(n, 3);
        // Nothing visible anywhere: the same.
        let mut b = Fake::new(1, |_, _| false);
        assert_eq!(run(&mut b, AdaptiveSampling::new(2, 16).unwrap()).1, 2);
    }

    #[test]
    fn refines_around_a_finder_until_a_round_finds_nothing() {
        // Object 0 is seen from the middle of the cell only (|x − 2| < 1.2, no corner): a seed
        // finds it, then its children and the next Halton point find nothing more → stop.
        let mut b = Fake::new(1, |p, _| (p.x - 2.0).abs() < 1.2);
        let (out, n) = run(&mut b, AdaptiveSampling::new(1, 16).unwrap());
        assert!(out.iter().any(|d| d.get(0) > 0.0));
        // One seed, then one round of ≤ 4 children + 1 Halton point, none of them new.
        assert!((2..=6).contains(&n), "{n} points");
    }

    #[test]
    fn finds_an_object_seen_from_a_sliver_next_to_what_a_seed_found() {
        // Object 0 seen where x < 2.2 (a seed sees it); object 1 only in a narrow band
        // 2.6 < x < 3.2 and z > 1.5: found by walking from a finder, not by the two seeds.
        let mut b = Fake::new(2, |p, i| match i {
            0 => p.x < 2.2 && p.x > 0.5,
            _ => p.x > 2.6 && p.x < 3.2 && p.z > 1.5,
        });
        let seeds_only: Vec<Vec3> = (1..=2).map(|k| crate::dov::sampling::halton_point(&cell(), k)).collect();
        assert!(seeds_only.iter().all(|p| !(p.x > 2.6 && p.x < 3.2 && p.z > 1.5)));
        let (out, _) = run(&mut b, AdaptiveSampling::new(2, 16).unwrap());
        assert!(out.iter().any(|d| d.get(1) > 0.0));
    }

    #[test]
    fn an_unseen_candidate_keeps_the_cell_sampling() {
        // Object 1 is seen from a small square of the cell only (4 % of it), which no seed
        // hits: without the candidate the cell stops after its seeds, with it the cell explores
        // (one Halton point a round: the 19th is the first inside) until a point sees it, and
        // stops soon after.
        let sees = |p: Vec3, i: u32| match i {
            0 => true,
            _ => p.x > 3.0 && p.x < 3.8 && p.z > 3.0 && p.z < 3.8,
        };
        let mut b = Fake::new(2, sees);
        let (out, n) = run(&mut b, AdaptiveSampling::new(2, 64).unwrap());
        assert_eq!(n, 2);
        assert!(out.iter().all(|d| d.get(1) == 0.0));
        let mut b = Fake::new(2, sees);
        let (out, n) = run_with(&mut b, AdaptiveSampling::new(2, 64).unwrap(), &HashSet::from([1]));
        let finder = out.iter().position(|d| d.get(1) > 0.0).expect("the candidate is found");
        // After the finder, one round of its children (≤ 4) and a Halton point, then the stop.
        assert!(n - (finder + 1) <= 5, "{n} points, the finder was point {finder}");
        // A candidate never seen costs the whole budget, and no more.
        let mut b = Fake::new(2, |_, i| i == 0);
        assert_eq!(run_with(&mut b, AdaptiveSampling::new(2, 20).unwrap(), &HashSet::from([1])).1, 20);
    }

    #[test]
    fn never_exceeds_the_budget() {
        // Every distinct place shows a new object: only the budget stops the rounds.
        let mut b = Fake::new(4096, |p, i| i == ((p.x * 97.0 + p.z * 13.0) as u32 % 4096));
        assert_eq!(run(&mut b, AdaptiveSampling::new(2, 9).unwrap()).1, 9);
    }

    #[test]
    fn names_round_trip_and_bad_ones_are_refused() {
        assert_eq!("adaptive".parse::<AdaptiveSampling>().unwrap(), AdaptiveSampling::DEFAULT);
        let a: AdaptiveSampling = "adaptive:3:24".parse().unwrap();
        assert_eq!(a, AdaptiveSampling { seeds: 3, budget: 24 });
        assert_eq!(a.to_string().parse::<AdaptiveSampling>().unwrap(), a);
        for bad in ["adaptive:0:4", "adaptive:5:4", "adaptive:x:4", "adaptive:3", "halton"] {
            assert!(bad.parse::<AdaptiveSampling>().is_err(), "{bad}");
        }
    }
}
