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
/// (robust weight above one half). Away from the outlines the surface is the template's
/// interpolation, which the X-rays never see; there the deformation's smoothing, not the patient,
/// decides the shape, and a whole-surface fit follows it. None when too few such vertices.
pub fn observed_part_sphere(mesh: &Mesh, obs: &[Observation]) -> Option<Sphere> {
    let mut ids: Vec<u32> = obs
        .iter()
        .filter(|o| o.weight > 0.5)
        .map(|o| o.vertex)
        .filter(|&v| (v as usize) < mesh.vertex_count())
        .collect();
    ids.sort_unstable();
    ids.dedup();
    let pts: Vec<Point3<f64>> = ids.iter().map(|&v| mesh.vertices[v as usize]).collect();
    part_sphere(&pts)
}

/// The robust sphere of a part's vertices `pts`; None when fewer than `MIN_SPHERE_VERTICES` or
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
