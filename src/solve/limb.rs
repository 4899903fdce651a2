//! The acetabular sphere straight from the outlines. Where the acetabulum's dome forms the
//! outline of a view, the outline is the limb of its sphere: the ray through such a point grazes
//! the sphere, at distance R from its centre S. Where the rim forms the outline, the ray passes
//! through the sphere (distance < R). So the sphere is fitted to every view's outline points with
//! a one-sided loss: the residual d_i(S) - R counts in full outside and near the limb, and rim
//! points well inside count less and less (Cauchy). No correspondences and no starting pose are
//! needed: the start is triangulated from the outlines' centroids.

use crate::geom::Curve;
use crate::views::Camera;
use nalgebra::{Matrix4, Point3, Vector3, Vector4};

/// A sphere found from the outlines.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LimbSphere {
    /// Centre, mm.
    pub center: Point3<f64>,
    /// Radius, mm.
    pub radius: f64,
    /// The inside scale the fit ended on (the noise floor), mm.
    pub scale_mm: f64,
    /// Share of the outline points on the limb (within two SDs of it).
    pub limb_share: f64,
}

/// Why no sphere came out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LimbError {
    /// Fewer than two views with outline points.
    #[error("sphere from outlines: needs at least two views with outline points, got {views}")]
    TooFewViews {
        /// Views with points.
        views: usize,
    },
    /// The views' centroid rays do not meet (parallel views).
    #[error("sphere from outlines: the outlines' centroid rays do not meet (parallel views)")]
    Degenerate,
    /// The fit left the finite numbers.
    #[error("sphere from outlines: the fit did not stay finite")]
    NotFinite,
    /// A noise floor that is not finite and >= 0.
    #[error("sphere from outlines: the noise floor {value} mm must be finite and >= 0")]
    Scale {
        /// The floor, mm.
        value: f64,
    },
}

/// Most halvings of the inside scale (from half the radius, 64 reach 1e-19 of it).
const MAX_HALVINGS: usize = 64;

struct Ray {
    origin: Point3<f64>,
    dir: Vector3<f64>,
}

fn rays(cams: &[Camera], observed: &[Vec<Curve>]) -> (Vec<Ray>, usize) {
    let mut out = Vec::new();
    let mut views = 0;
    for (cam, curves) in cams.iter().zip(observed) {
        let before = out.len();
        let origin = cam.center();
        for c in curves {
            for p in &c.points {
                if p.x.is_finite() && p.y.is_finite() {
                    out.push(Ray {
                        origin,
                        dir: cam.ray(p),
                    });
                }
            }
        }
        if out.len() > before {
            views += 1;
        }
    }
    (out, views)
}

/// The point closest (least squares) to every view's ray through its outline centroid, and a
/// radius from the outlines' mean distance to their centroids.
fn start(cams: &[Camera], observed: &[Vec<Curve>]) -> Result<(Point3<f64>, f64), LimbError> {
    let mut a = nalgebra::Matrix3::zeros();
    let mut b = Vector3::zeros();
    let mut spreads = Vec::new();
    for (cam, curves) in cams.iter().zip(observed) {
        let pts: Vec<_> = curves.iter().flat_map(|c| c.points.iter()).collect();
        if pts.is_empty() {
            continue;
        }
        let n = pts.len() as f64;
        let c = pts
            .iter()
            .fold(nalgebra::Vector2::zeros(), |s, p| s + p.coords)
            / n;
        let spread = pts.iter().map(|p| (p.coords - c).norm()).sum::<f64>() / n;
        let d = cam.ray(&nalgebra::Point2::from(c));
        let m = nalgebra::Matrix3::identity() - d * d.transpose();
        let o = cam.center().coords;
        a += m;
        b += m * o;
        spreads.push((cam, spread));
    }
    let s = a
        .try_inverse()
        .filter(|_| spreads.len() >= 2)
        .ok_or(LimbError::Degenerate)?
        * b;
    let s = Point3::from(s);
    let r = spreads
        .iter()
        .map(|(cam, spread)| spread / cam.pixels_per_mm_at(&s))
        .sum::<f64>()
        / spreads.len() as f64;
    Ok((s, r))
}

/// Fit the sphere to the outlines of every view. `min_scale_mm` floors the limb noise scale
/// (the annotation's noise in mm at the object; it keeps a noise-free outline from collapsing
/// the scale to zero).
pub fn limb_sphere(
    cams: &[Camera],
    observed: &[Vec<Curve>],
    min_scale_mm: f64,
) -> Result<LimbSphere, LimbError> {
    if !(min_scale_mm.is_finite() && min_scale_mm >= 0.0) {
        return Err(LimbError::Scale {
            value: min_scale_mm,
        });
    }
    let (rays, views) = rays(cams, observed);
    if views < 2 {
        return Err(LimbError::TooFewViews { views });
    }
    let (mut s, mut r) = start(cams, observed)?;
    let dist = |s: &Point3<f64>, ray: &Ray| (s - ray.origin).cross(&ray.dir).norm();
    // Graduated non-convexity: the inside scale starts wide (every point pulls, as for a
    // least-squares circle) and halves until it reaches the noise floor, so the rim points let
    // go only once the sphere is near.
    let mut c = (0.5 * r).max(min_scale_mm);
    for halving in 0.. {
        for _ in 0..30 {
            let mut h = Matrix4::<f64>::zeros();
            let mut g = Vector4::<f64>::zeros();
            for ray in &rays {
                let v = s - ray.origin;
                let perp = v - ray.dir * v.dot(&ray.dir);
                let n = perp.norm();
                if n < 1e-12 {
                    continue;
                }
                let e = n - r;
                let w = if e >= 0.0 {
                    1.0
                } else {
                    1.0 / (1.0 + (e / c).powi(2))
                };
                // d dist / dS: the unit vector from the ray's closest point to S.
                let j = Vector4::new(perp.x / n, perp.y / n, perp.z / n, -1.0);
                h += w * j * j.transpose();
                g += w * j * e;
            }
            let Some(step) = (h + Matrix4::identity() * 1e-9)
                .try_inverse()
                .map(|hi| hi * g)
            else {
                return Err(LimbError::NotFinite);
            };
            s -= Vector3::new(step.x, step.y, step.z);
            r -= step.w;
            if !(s.coords.iter().all(|v| v.is_finite()) && r.is_finite() && r > 0.0) {
                return Err(LimbError::NotFinite);
            }
            if step.norm() < 1e-5 {
                break;
            }
        }
        if c <= min_scale_mm || halving >= MAX_HALVINGS {
            break;
        }
        c = (0.5 * c).max(min_scale_mm);
    }
    let scale = c;
    let res: Vec<f64> = rays.iter().map(|ray| dist(&s, ray) - r).collect();
    let on = res.iter().filter(|e| e.abs() <= 2.0 * scale).count();
    Ok(LimbSphere {
        center: s,
        radius: r,
        scale_mm: scale,
        limb_share: on as f64 / res.len().max(1) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contours::model_contour;
    use crate::sim::{simulated_views, XrayGeometry};
    use crate::template::{spherical_cap, Placement};
    use nalgebra::Unit;

    /// Outlines of a spherical cap (80 degrees, opening lateral and a little anterior) in the
    /// three study views, and the cap's placement.
    fn cap_outlines() -> (Vec<Camera>, Vec<Vec<Curve>>, Placement) {
        let place = Placement {
            center: Point3::new(90.0, 20.0, -560.0),
            radius: 27.0,
            axis: Unit::new_normalize(Vector3::new(1.0, 0.4, -0.5)),
        };
        let mesh = place.place(&spherical_cap(1.0, 4000, 80f64.to_radians()));
        let cams = simulated_views(&XrayGeometry::default(), &place.center);
        let observed = cams
            .iter()
            .map(|c| {
                let m = model_contour(&mesh, c, None).unwrap();
                vec![Curve {
                    points: m.points,
                    closed: true,
                }]
            })
            .collect();
        (cams, observed, place)
    }

    fn matches(ls: &LimbSphere, p: &Placement) -> bool {
        (ls.center - p.center).norm() < 0.5 && (ls.radius - p.radius).abs() < 0.3
    }

    #[test]
    fn finds_the_sphere_of_a_cap_from_its_outlines_alone() {
        let (cams, observed, place) = cap_outlines();
        let ls = limb_sphere(&cams, &observed, 0.5).unwrap();
        assert!(matches(&ls, &place), "{ls:?} vs {place:?}");
        // The outline is part limb, part rim.
        assert!(ls.limb_share > 0.3 && ls.limb_share < 0.95, "{ls:?}");
        // Companion: a sphere 1 mm too large, or 1 mm off in depth, is not a match.
        let big = LimbSphere {
            radius: place.radius + 1.0,
            center: place.center,
            ..ls
        };
        let deep = LimbSphere {
            center: place.center + Vector3::new(0.0, 1.0, 0.0),
            radius: place.radius,
            ..ls
        };
        assert!(!matches(&big, &place) && !matches(&deep, &place));
    }

    #[test]
    fn a_least_squares_circle_fit_would_be_fooled_by_the_rim() {
        // What the one-sided loss is for: with every point counted in full (an inside scale too
        // wide to let the rim go) the sphere comes out measurably smaller.
        let (cams, observed, place) = cap_outlines();
        let wide = limb_sphere(&cams, &observed, 1e3).unwrap();
        assert!(!matches(&wide, &place), "{wide:?}");
        assert!(wide.radius < place.radius - 0.3, "{wide:?}");
    }

    #[test]
    fn one_view_or_nothing_is_an_error() {
        let (cams, observed, _) = cap_outlines();
        assert_eq!(
            limb_sphere(&cams[..1], &observed[..1], 0.5),
            Err(LimbError::TooFewViews { views: 1 })
        );
        let empty = vec![vec![]; 3];
        assert_eq!(
            limb_sphere(&cams, &empty, 0.5),
            Err(LimbError::TooFewViews { views: 0 })
        );
    }

    #[test]
    fn an_unusable_noise_floor_is_an_error_not_an_endless_loop() {
        let (cams, observed, place) = cap_outlines();
        for bad in [f64::NAN, -1.0, f64::INFINITY] {
            assert!(matches!(
                limb_sphere(&cams, &observed, bad),
                Err(LimbError::Scale { .. })
            ));
        }
        // Companion: a zero floor is allowed and ends (the halvings are bounded).
        let zero = limb_sphere(&cams, &observed, 0.0).unwrap();
        assert!(zero.radius.is_finite() && (zero.radius - place.radius).abs() < 3.0);
    }
}
