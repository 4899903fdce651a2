//! The cup sphere, the one estimator of the cup: fitted to the part of the result the X-rays
//! observe (`CupEstimator::ObservedPart`, the default) or, with a population prior, to the part
//! most acetabula have (`CupEstimator::PriorRegion`), its diameter corrected by the calibration
//! (`CupParams::corrected`: the estimator's learned bias and shrink). `reconstruct` reports it and the uncertainty's resamples go
//! through it too, so the +- and the size probabilities describe the number they stand beside.

use super::params::{CupEstimator, CupParams};
use crate::correspond::Observation;
use crate::geom::Mesh;
use crate::geom::{fit_sphere_robust, Sphere, SphereFitError};
use crate::prior::{opens_to_plus_x, to_prior_frame, ShapePrior};
use nalgebra::Point3;

/// Fewest distinct observed vertices the cup sphere is fitted to.
const MIN_SPHERE_VERTICES: usize = 30;

/// The cup sphere of a reconstructed surface and the sphere of its whole surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CupSpheres {
    /// The cup: the estimator's sphere (`observed_part_sphere` or `prior_region_sphere`), or the
    /// whole surface's when too few vertices lie in its part; its diameter corrected
    /// (`CupParams::corrected`).
    pub cup: Sphere,
    /// The estimator's sphere as fitted, before the correction: the cup's geometry (its rim
    /// lies on it), where `cup` is the size the calibration reads from it.
    pub fitted: Sphere,
    /// The sphere fitted (robustly) to every vertex.
    pub surface: Sphere,
}

/// The population prior and the centre its directions are taken from (the sphere prior's), for
/// `CupEstimator::PriorRegion`.
pub type PriorRegion<'a> = (&'a ShapePrior, Point3<f64>);

/// The cup estimator `cup` of `mesh` under the correspondences `obs` (with their robust
/// weights): its part's sphere, falling back to the whole surface's, the diameter corrected by
/// the calibration's bias and shrink (`CupParams::corrected`). `region` is needed by
/// `CupEstimator::PriorRegion` (without it, the whole surface's sphere).
pub fn cup_spheres(
    mesh: &Mesh,
    obs: &[Observation],
    cup: &CupParams,
    region: Option<PriorRegion>,
) -> Result<CupSpheres, SphereFitError> {
    let surface = fit_sphere_robust(&mesh.vertices)?;
    let part = match cup.estimator {
        CupEstimator::ObservedPart => observed_part_sphere(mesh, obs),
        CupEstimator::PriorRegion => region.and_then(|(p, c)| prior_region_sphere(mesh, p, &c)),
    };
    let fitted = part.unwrap_or(surface);
    let mut sphere = fitted;
    // `CupParams::corrected` on the radius: without a shrink exactly the bias's half.
    sphere.radius -= 0.5 * (cup.bias_mm + cup.shrink * (sphere.diameter() - cup.shrink_to_mm));
    if !(sphere.radius > 0.0) {
        // A diameter smaller than the bias: no cup (the guards refuse any under 30 mm anyway).
        return Err(SphereFitError::Degenerate);
    }
    Ok(CupSpheres {
        cup: sphere,
        fitted,
        surface,
    })
}

/// Robust sphere fit to the reconstructed vertices that the correspondences hold to the outlines
/// (robust weight above one half), one point per pair: a vertex that the outlines of several
/// views hold counts once for each (the rim's vertices, seen in every view, weigh as the evidence
/// they carry; docs/population.md, "The cup counts a vertex once per view": cup RMS shells /
/// atlas 0.97 / 0.95 -> 0.93 / 0.86 mm at seed 7, 0.96 / 0.97 -> 0.90 / 0.86 at seed 9, against
/// each vertex once). Away from the outlines the surface is the template's interpolation, which
/// the X-rays never see; there the deformation's smoothing, not the patient, decides the shape,
/// and a whole-surface fit follows it. The sphere's `rms` is over the distinct vertices. None
/// when fewer than `MIN_SPHERE_VERTICES` distinct vertices are held.
pub fn observed_part_sphere(mesh: &Mesh, obs: &[Observation]) -> Option<Sphere> {
    let mut ids: Vec<u32> = obs
        .iter()
        .filter(|o| o.weight > 0.5)
        .map(|o| o.vertex)
        .filter(|&v| (v as usize) < mesh.vertex_count())
        .collect();
    ids.sort_unstable();
    let mut distinct = ids.clone();
    distinct.dedup();
    if distinct.len() < MIN_SPHERE_VERTICES {
        return None;
    }
    let pts: Vec<Point3<f64>> = ids.iter().map(|&v| mesh.vertices[v as usize]).collect();
    let mut sphere = part_sphere(&pts)?;
    // Its RMS over the part's vertices, each once: how far the observed surface lies from the
    // sphere (the rough guard's measure), which the rim's vertices, held in every view, would
    // otherwise dilute.
    let c = sphere.center_point();
    let sq: f64 = distinct
        .iter()
        .map(|&v| ((mesh.vertices[v as usize] - c).norm() - sphere.radius).powi(2))
        .sum();
    sphere.rms = (sq / distinct.len() as f64).sqrt();
    Some(sphere)
}

/// The robust sphere of a part's points `pts`; None when fewer than `MIN_SPHERE_VERTICES` or
/// the fit fails.
fn part_sphere(pts: &[Point3<f64>]) -> Option<Sphere> {
    if pts.len() < MIN_SPHERE_VERTICES {
        return None;
    }
    fit_sphere_robust(pts).ok().filter(|s| s.radius.is_finite())
}

/// Share of the training acetabula that must reach a direction for `prior_region_sphere` to
/// count the reconstructed vertices there.
pub const REGION_MIN_COVERAGE: f64 = 0.5;

/// Robust sphere fit to the reconstructed vertices in the region the population prior's training
/// acetabula share (at least `REGION_MIN_COVERAGE` of them reach the vertex's direction from
/// `center`, in the prior's frame): the part of the surface that is acetabulum on most patients,
/// rather than the part the outlines happen to trace. None when too few vertices lie there.
pub fn prior_region_sphere(
    mesh: &Mesh,
    prior: &ShapePrior,
    center: &Point3<f64>,
) -> Option<Sphere> {
    let mirrored = opens_to_plus_x(&mesh.vertices, center);
    let pts: Vec<Point3<f64>> = mesh
        .vertices
        .iter()
        .filter(|v| {
            let d = *v - center;
            d.try_normalize(1e-12).is_some_and(|u| {
                prior.coverage_at(&to_prior_frame(u, mirrored)) >= REGION_MIN_COVERAGE
            })
        })
        .copied()
        .collect();
    part_sphere(&pts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prior::deviation_field;
    use crate::template::{hemisphere, spherical_cap};

    /// Caps of radius 24-26 reaching `max_polar_deg` from their dome (at -z; the caps are
    /// symmetric about z, so the prior frame's mirroring in x leaves them as they are).
    fn prior_of_caps(max_polar_deg: f64) -> ShapePrior {
        let fields: Vec<_> = (0..3)
            .map(|k| {
                let m = spherical_cap(24.0 + k as f64, 1500, max_polar_deg.to_radians());
                let s = fit_sphere_robust(&m.vertices).unwrap();
                (format!("c{k}"), deviation_field(&m.vertices, &s).0)
            })
            .collect();
        ShapePrior::learn(&fields, 0).unwrap()
    }

    /// A hemisphere of radius 25 (dome at -z) whose band beyond 60 degrees from the dome flares
    /// out to a lip 20 % wider: the acetabulum's margin that a whole-surface fit follows.
    fn flared() -> Mesh {
        let mut m = hemisphere(25.0, 2500);
        for v in m.vertices.iter_mut() {
            let polar = (-v.z / 25.0).clamp(-1.0, 1.0).acos().to_degrees();
            if polar > 60.0 {
                let s = 1.0 + 0.2 * (polar - 60.0) / 30.0;
                *v = Point3::new(v.x * s, v.y * s, v.z);
            }
        }
        m
    }

    #[test]
    fn the_prior_region_sphere_fits_where_the_training_acetabula_reach() {
        let m = flared();
        let c = Point3::origin();
        let whole = fit_sphere_robust(&m.vertices).unwrap();
        let region = prior_region_sphere(&m, &prior_of_caps(55.0), &c).unwrap();
        assert!((region.radius - 25.0).abs() < 0.05, "{region:?}");
        assert!((whole.radius - 25.0).abs() > 0.5, "{whole:?}");
        // Companion: a prior whose acetabula reach the whole hemisphere takes the lip in.
        let wide = prior_of_caps(90.0);
        let r = prior_region_sphere(&m, &wide, &c).unwrap();
        assert!((r.radius - 25.0).abs() > 0.3, "{r:?}");
        // A region the surface does not reach gives no sphere (a prior of caps turned away).
        let away: Vec<Point3<f64>> = m
            .vertices
            .iter()
            .map(|v| Point3::new(v.x, v.y, -v.z))
            .collect();
        let away_mesh = m.with_vertices(away);
        assert!(prior_region_sphere(
            &away_mesh,
            &prior_of_caps(30.0),
            &Point3::new(0.0, 0.0, 0.0)
        )
        .is_none());
    }

    /// A pair of `vertex` in `view` of weight `weight`.
    fn held(view: usize, vertex: u32, weight: f64) -> Observation {
        Observation {
            view,
            vertex,
            target: nalgebra::Point2::origin(),
            weight,
            normal: nalgebra::Vector2::zeros(),
        }
    }

    #[test]
    fn the_observed_part_counts_a_vertex_once_per_view_that_holds_it() {
        // Two rings of 30 vertices on a sphere of radius 25 (held in one view each) and one of
        // 30 on a sphere of radius 20 about the same centre (held in three views each): one
        // point per pair, so the fit is the robust sphere of the points with the three-view
        // ring given three times.
        let ring = |r: f64, n: usize, z: f64| -> Vec<Point3<f64>> {
            (0..n)
                .map(|k| {
                    let a = k as f64 / n as f64 * std::f64::consts::TAU;
                    let h = (r * r - z * z).sqrt();
                    Point3::new(h * a.cos(), h * a.sin(), z)
                })
                .collect()
        };
        let mut vertices = ring(25.0, 30, -5.0);
        vertices.extend(ring(25.0, 30, -15.0));
        vertices.extend(ring(20.0, 30, -10.0));
        // Triangles only to make a mesh of them; the part's sphere reads its vertices.
        let triangles = (0..88u32).map(|k| [k, k + 1, k + 2]).collect();
        let mesh = Mesh::new(vertices, triangles).unwrap();
        let mut obs: Vec<Observation> = (0..60u32).map(|v| held(v as usize % 3, v, 1.0)).collect();
        for v in 60..90 {
            obs.extend((0..3).map(|view| held(view, v, 1.0)));
        }
        // Pairs of weight 0.5 or less (the rim's surplus, robustly damped pairs) are left out.
        obs.extend((0..60).map(|v| held(1, v, 0.3)));
        let once: Vec<Point3<f64>> = mesh.vertices.clone();
        let mut thrice = once.clone();
        thrice.extend_from_slice(&once[60..]);
        thrice.extend_from_slice(&once[60..]);
        let got = observed_part_sphere(&mesh, &obs).unwrap();
        let want = fit_sphere_robust(&thrice).unwrap();
        assert!((got.radius - want.radius).abs() < 1e-9, "{got:?} {want:?}");
        // Its RMS is over the vertices, each once (companion: the points' RMS, with the
        // three-view ring three times, is another number).
        let c = got.center_point();
        let rms = (once
            .iter()
            .map(|p| ((p - c).norm() - got.radius).powi(2))
            .sum::<f64>()
            / once.len() as f64)
            .sqrt();
        assert!((got.rms - rms).abs() < 1e-9, "{} {rms}", got.rms);
        assert!((want.rms - rms).abs() > 0.1, "{} {rms}", want.rms);
        // Companion: the each-vertex-once fit is another sphere, and the comparison tells.
        let each_once = fit_sphere_robust(&once).unwrap();
        assert!(
            (each_once.radius - got.radius).abs() > 0.1,
            "{each_once:?} {got:?}"
        );
        // Too few distinct vertices however often they are held: no sphere.
        let few: Vec<Observation> = (0..20)
            .flat_map(|v| (0..3).map(move |view| held(view, v, 1.0)))
            .collect();
        assert!(observed_part_sphere(&mesh, &few).is_none());
    }

    #[test]
    fn the_cup_is_the_estimators_sphere_less_the_bias() {
        let m = flared();
        let prior = prior_of_caps(55.0);
        let region = Some((&prior, Point3::origin()));
        let mut cup = CupParams {
            estimator: CupEstimator::PriorRegion,
            ..Default::default()
        };
        let plain = cup_spheres(&m, &[], &cup, region).unwrap();
        assert!((plain.cup.diameter() - 50.0).abs() < 0.1, "{plain:?}");
        cup.bias_mm = 0.8;
        let less = cup_spheres(&m, &[], &cup, region).unwrap();
        assert!((plain.cup.diameter() - less.cup.diameter() - 0.8).abs() < 1e-12);
        assert_eq!(plain.cup.center, less.cup.center);
        // The fitted sphere is the estimator's, before the correction.
        assert_eq!(less.fitted, plain.cup);
        // Companion: without correspondences the observed part is empty, so the observed-part
        // estimator falls back to the whole surface, another sphere.
        cup.estimator = CupEstimator::ObservedPart;
        let obs = cup_spheres(&m, &[], &cup, region).unwrap();
        assert_eq!(obs.cup.radius, obs.surface.radius - 0.4);
        assert!((obs.cup.diameter() - less.cup.diameter()).abs() > 0.5);
        // A shrink takes its share of the departure from `shrink_to_mm` off as well: the prior
        // region's 50 mm, 0.8 mm bias, a quarter of the 6 mm above 44 mm.
        cup.estimator = CupEstimator::PriorRegion;
        cup.shrink = 0.25;
        cup.shrink_to_mm = 44.0;
        let pulled = cup_spheres(&m, &[], &cup, region).unwrap();
        let expected = plain.cup.diameter() - 0.8 - 0.25 * (plain.cup.diameter() - 44.0);
        assert!(
            (pulled.cup.diameter() - expected).abs() < 1e-12,
            "{pulled:?}"
        );
        assert!((cup.corrected(plain.cup.diameter()) - expected).abs() < 1e-12);
        // Companion: toward its own diameter the shrink moves nothing.
        cup.shrink_to_mm = plain.cup.diameter();
        let still = cup_spheres(&m, &[], &cup, region).unwrap();
        assert!((still.cup.diameter() - less.cup.diameter()).abs() < 1e-12);
    }
}
