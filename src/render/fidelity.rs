//! Image fidelity of an answer against full detail (docs/render.md, "The metrics"): PSNR of the shaded images and
//! the share of pixels whose coverage differs.
//!
//! - **PSNR** over the R, G and B channels of two 8-bit images of one size:
//!   `MSE = Σ (a − b)² / (3·pixels)`, `PSNR = 10·log₁₀(255² / MSE)` dB, `+∞` when they are equal.
//!   Above 30 dB counts as "practically unaltered" (the seeds).
//! - **Coverage difference**: the share of pixels where one image shows a surface and the other
//!   background, or both show a surface at depths further apart than a relative tolerance
//!   (`|dₐ − d_b| > tol · max(dₐ, d_b)`).

use serde::{Deserialize, Serialize};

use super::{ColorMode, Image, NO_ITEM, Renderer, View};
use crate::error::Result;
use crate::query::Session;

/// Default relative depth tolerance of [`coverage_diff`]: 1 %.
pub const DEFAULT_DEPTH_TOLERANCE: f32 = 0.01;

/// PSNR in dB of two RGBA8 buffers of equal length (alpha ignored); `+∞` when the RGB are
/// equal. Panics when the lengths differ or are not a multiple of 4.
pub fn psnr_rgba(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len(), "PSNR of images of different sizes");
    assert!(a.len().is_multiple_of(4), "RGBA8 buffers hold 4 bytes per pixel");
    let pixels = a.len() / 4;
    if pixels == 0 {
        return f64::INFINITY;
    }
    let sum: u64 = a
        .chunks_exact(4)
        .zip(b.chunks_exact(4))
        .map(|(p, q)| (0..3).map(|c| (i64::from(p[c]) - i64::from(q[c])).pow(2) as u64).sum::<u64>())
        .sum();
    if sum == 0 {
        return f64::INFINITY;
    }
    let mse = sum as f64 / (3 * pixels) as f64;
    10.0 * (255.0f64 * 255.0 / mse).log10()
}

/// PSNR in dB of two images' RGB (see [`psnr_rgba`]). Panics when their sizes differ.
pub fn psnr(a: &Image, b: &Image) -> f64 {
    assert_eq!((a.width, a.height), (b.width, b.height), "PSNR of images of different sizes");
    psnr_rgba(&a.rgba, &b.rgba)
}

/// Share of pixels (0..=1) whose coverage differs: surface in one image and background in the
/// other, or surfaces whose depths differ by more than `depth_tolerance` relative to the
/// further one. Panics when the sizes differ.
pub fn coverage_diff(a: &Image, b: &Image, depth_tolerance: f32) -> f64 {
    assert_eq!((a.width, a.height), (b.width, b.height), "coverage of images of different sizes");
    let n = a.ids.len();
    if n == 0 {
        return 0.0;
    }
    let differ = (0..n)
        .filter(|&i| {
            let (ca, cb) = (a.ids[i] != NO_ITEM, b.ids[i] != NO_ITEM);
            if ca != cb {
                return true;
            }
            let (da, db) = (a.depth[i], b.depth[i]);
            ca && (da - db).abs() > depth_tolerance * da.max(db)
        })
        .count();
    differ as f64 / n as f64
}

/// Both metrics of one image against a reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fidelity {
    /// dB; `+∞` for identical images (serialised as `null` in JSON).
    pub psnr: f64,
    /// Share of pixels, 0..=1, with [`DEFAULT_DEPTH_TOLERANCE`].
    pub coverage_diff: f64,
    /// Share of pixels where only one image shows a surface (coverage difference without the
    /// depth test: the silhouettes alone).
    pub silhouette_diff: f64,
}

/// The fidelity of what a walkthrough `session` draws from `view`
/// ([`Renderer::render_session`]) against full detail from the same view, both shaded. For a
/// fair number the view should lie inside the session's own frustum (REVIEW: `fov_deg` both
/// ways), else the objects it culled at the image's edges count as differences.
pub fn of_session(renderer: &Renderer, session: &Session, view: &View) -> Result<Fidelity> {
    let image = renderer.render_session(session, view)?;
    let full = renderer.render_full(session.database(), view, ColorMode::Shaded)?;
    Ok(compare(&image, &full))
}

/// The fidelity of `image` against `reference` (e.g. an answer's view against full detail).
pub fn compare(image: &Image, reference: &Image) -> Fidelity {
    Fidelity {
        psnr: psnr(image, reference),
        coverage_diff: coverage_diff(image, reference, DEFAULT_DEPTH_TOLERANCE),
        silhouette_diff: coverage_diff(image, reference, f32::INFINITY),
    }
}
