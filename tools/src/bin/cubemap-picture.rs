//! Draws the object-ID cube map that the DoV measurement renders at one street point of the
//! default city: the six 90° faces unfolded as a cross, each object in its own colour, surfaces
//! seen from behind darkened. The README's picture. Each coloured texel adds its solid angle to
//! its object's DoV.
//!
//! `cargo run --release -p hdov-tools --bin cubemap-picture -- [OUT.png] [R]`

use clap::Parser;
use glam::Vec3;
use hdov::city::{CityParams, CityScale};
use hdov::dov::{BACK_FACE_BIT, CpuBackend, DovBackend, IdCube, NO_OBJECT};
use plotters::prelude::*;

#[derive(Parser)]
#[command(
    name = "cubemap-picture",
    about = "Draws the object-ID cube map that the DoV measurement renders at one street point of the default city",
    long_about = "Draws the object-ID cube map that the DoV measurement renders at one street point of the default city\n\
                  (seed 1; the grid corner near the middle that sees the most objects from the street), with the CPU\n\
                  ray caster: the six 90° faces unfolded as a cross, each object in its own colour, surfaces seen from\n\
                  behind darkened. Prints the point, the objects visible and the sky's share.\n\
                  \n\
                  Makes: the README's picture docs/cubemap.png (`cubemap-picture`, R = 192)."
)]
struct Args {
    /// The PNG written (4R × 3R pixels).
    #[arg(value_name = "OUT.png", default_value = "docs/cubemap.png")]
    out: String,
    /// Cube-map resolution R (texels per face edge).
    #[arg(default_value_t = 192, value_parser = clap::value_parser!(u32).range(1..))]
    r: u32,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args { out, r } = Args::parse();
    let scene = hdov::city::generate(&CityParams { seed: 1, scale: CityScale::Default, ..Default::default() })?;
    let grid = scene.grid.clone().expect("the city brings a grid");
    // The grid corner near the city's middle that sees the most objects from the street (not from
    // inside a building), at eye height: found with a coarse cube map.
    let mut probe = CpuBackend::new(&scene, 16)?;
    let mid = [grid.dims[0] / 2, grid.dims[2] / 2];
    let mut best = (0usize, Vec3::ZERO);
    for dx in 0..6 {
        for dz in 0..6 {
            let q = grid.corner_position([mid[0] + dx, 0, mid[1] + dz]) + Vec3::Y * 0.2;
            let d = probe.measure(q)?;
            if d.back_face < 0.01 && d.empty < 0.6 && d.objects.len() > best.0 {
                best = (d.objects.len(), q);
            }
        }
    }
    let p = best.1;
    let mut backend = CpuBackend::new(&scene, r)?;
    let mut ids = IdCube::new(r);
    backend.render_ids(p, &mut ids)?;
    let dov = ids.dov(backend.cube_map());
    println!("{out}: cube map at {p} (R = {r}): {} objects visible, sky {:.3}", dov.objects.len(), dov.empty);

    // Cross layout, 4 faces wide and 3 high: −X +Z +X −Z in the middle row, +Y above +Z, −Y below.
    // Face order in the cube map: +X, −X, +Y, −Y, +Z, −Z.
    let cells: [(usize, u32, u32); 6] = [(0, 2, 1), (1, 0, 1), (2, 1, 0), (3, 1, 2), (4, 1, 1), (5, 3, 1)];
    let root = BitMapBackend::new(&out, (4 * r, 3 * r)).into_drawing_area();
    root.fill(&WHITE)?;
    let n = r as usize;
    for (face, cx, cy) in cells {
        for row in 0..n {
            for col in 0..n {
                let id = ids.ids[face * n * n + row * n + col];
                let below_horizon = backend.cube_map().texel_direction(face, row as u32, col as u32).y < 0.0;
                let colour = colour_of(id, below_horizon);
                root.draw_pixel((cx as i32 * r as i32 + col as i32, cy as i32 * r as i32 + row as i32), &colour)?;
            }
        }
    }
    root.present()?;
    Ok(())
}

/// A stable, well-spread colour per object; empty directions pale blue above the horizon and
/// grey below (the city has no ground object), back faces dark.
fn colour_of(id: u32, below_horizon: bool) -> RGBColor {
    if id == NO_OBJECT {
        return if below_horizon { RGBColor(215, 215, 210) } else { RGBColor(200, 225, 245) };
    }
    let object = id & !BACK_FACE_BIT;
    let h = object.wrapping_mul(0x9E37_79B9).rotate_left(7);
    let c = [(h & 0xff) as u8, ((h >> 8) & 0xff) as u8, ((h >> 16) & 0xff) as u8].map(|v| 60 + v / 2);
    if id & BACK_FACE_BIT != 0 { RGBColor(c[0] / 4, c[1] / 4, c[2] / 4) } else { RGBColor(c[0], c[1], c[2]) }
}
