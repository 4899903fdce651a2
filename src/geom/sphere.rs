//! Sphere fit: algebraic (linear least squares on |p|^2 = 2 c.p + d), then geometric refinement
//! (Gauss-Newton on sum (|p - c| - r)^2).

use nalgebra::{Matrix4, Point3, Vector3, Vector4};

/// A sphere in mm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Sphere {
    /// Centre (x, y, z), mm.
    pub center: [f64; 3],
    /// Radius, mm.
    pub radius: f64,
    /// RMS of |p - c| - r over the fitted points.
    pub rms: f64,
}

impl Sphere {
    /// Twice the radius.
    pub fn diameter(&self) -> f64 {
        2.0 * self.radius
    }
    /// The centre as a point.
    pub fn center_point(&self) -> Point3<f64> {
        Point3::new(self.center[0], self.center[1], self.center[2])
    }
    /// The same sphere with its centre moved by `v` (what a fit to the points moved by `v`
    /// gives).
    pub fn moved(&self, v: &nalgebra::Vector3<f64>) -> Sphere {
        Sphere {
            center: (self.center_point() + v).into(),
            ..*self
        }
    }
}

/// Why no sphere could be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SphereFitError {
    /// Fewer than four points.
    #[error("a sphere needs at least 4 points, got {0}")]
    TooFewPoints(usize),
    /// The points are coplanar or coincide.
    #[error("the points are degenerate (coplanar or coincident); no unique sphere")]
    Degenerate,
}

/// Fit a sphere to points.
pub fn fit_sphere(points: &[Point3<f64>]) -> Result<Sphere, SphereFitError> {
    fit_sphere_weighted(points, None)
}

/// Robust sphere fit: iteratively reweighted with Tukey's biweight on the radial residuals
/// (cut-off 4.685 robust SDs, the SD from the median absolute residual), so that parts of a
/// reconstruction pulled off the sphere (a notch, a bulge) do not move the cup size.
pub fn fit_sphere_robust(points: &[Point3<f64>]) -> Result<Sphere, SphereFitError> {
    let mut s = fit_sphere(points)?;
    for _ in 0..10 {
        let c = s.center_point();
        let res: Vec<f64> = points.iter().map(|p| (p - c).norm() - s.radius).collect();
        let mut abs: Vec<f64> = res.iter().map(|r| r.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let scale = (1.4826 * abs[abs.len() / 2]).max(1e-6);
        let cut = 4.685 * scale;
        let w: Vec<f64> = res
            .iter()
            .map(|r| {
                if r.abs() < cut {
                    (1.0 - (r / cut).powi(2)).powi(2)
                } else {
                    0.0
                }
            })
            .collect();
        if w.iter().filter(|x| **x > 0.0).count() < 4 {
            break;
        }
        let next = fit_sphere_weighted(points, Some(&w))?;
        let moved = (next.center_point() - c).norm() + (next.radius - s.radius).abs();
        s = next;
        if moved < 1e-6 {
            break;
        }
    }
    Ok(s)
}

fn fit_sphere_weighted(
    points: &[Point3<f64>],
    weights: Option<&[f64]>,
) -> Result<Sphere, SphereFitError> {
    let wt = |i: usize| weights.map_or(1.0, |w| w[i]);
    if points.len() < 4 {
        return Err(SphereFitError::TooFewPoints(points.len()));
    }
    // Algebraic: [2x 2y 2z 1] [c; d] = |p|^2, centred for conditioning.
    let wsum: f64 = (0..points.len()).map(wt).sum();
    if !(wsum > 0.0) {
        return Err(SphereFitError::Degenerate);
    }
    let mean = points
        .iter()
        .enumerate()
        .map(|(i, p)| p.coords * wt(i))
        .sum::<Vector3<f64>>()
        / wsum;
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    for (i, p) in points.iter().enumerate() {
        let q = p.coords - mean;
        let row = Vector4::new(2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0);
        ata += row * row.transpose() * wt(i);
        atb += row * q.norm_squared() * wt(i);
    }
    let sol = ata
        .cholesky()
        .ok_or(SphereFitError::Degenerate)?
        .solve(&atb);
    let mut c = Vector3::new(sol[0], sol[1], sol[2]);
    let r2 = sol[3] + c.norm_squared();
    if !(r2 > 0.0) || !r2.is_finite() {
        return Err(SphereFitError::Degenerate);
    }
    let mut r = r2.sqrt();
    // Geometric refinement.
    for _ in 0..50 {
        let mut jtj = Matrix4::<f64>::zeros();
        let mut jtr = Vector4::<f64>::zeros();
        for (i, p) in points.iter().enumerate() {
            let d = p.coords - mean - c;
            let n = d.norm().max(1e-12);
            let res = n - r;
            let j = Vector4::new(-d.x / n, -d.y / n, -d.z / n, -1.0);
            jtj += j * j.transpose() * wt(i);
            jtr += j * res * wt(i);
        }
        let Some(ch) = jtj.cholesky() else { break };
        let step = -ch.solve(&jtr);
        c += Vector3::new(step[0], step[1], step[2]);
        r += step[3];
        if step.norm() < 1e-12 * (1.0 + r) {
            break;
        }
    }
    let rms = (points
        .iter()
        .map(|p| ((p.coords - mean - c).norm() - r).powi(2))
        .sum::<f64>()
        / points.len() as f64)
        .sqrt();
    let center = c + mean;
    if !(r > 0.0 && r.is_finite() && center.iter().all(|v| v.is_finite())) {
        return Err(SphereFitError::Degenerate);
    }
    Ok(Sphere {
        center: [center.x, center.y, center.z],
        radius: r.abs(),
        rms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_on_sphere_points_even_on_a_small_cap() {
        let c = Vector3::new(3.0, -4.0, 10.0);
        let pts: Vec<Point3<f64>> = (0..200)
            .map(|i| {
                let t = 0.6 * (i as f64 / 200.0); // a cap of 0.6 rad only
                let p = i as f64 * 2.399;
                Point3::from(
                    c + 27.5 * Vector3::new(t.sin() * p.cos(), t.sin() * p.sin(), -t.cos()),
                )
            })
            .collect();
        let s = fit_sphere(&pts).unwrap();
        assert!((s.radius - 27.5).abs() < 1e-9, "{}", s.radius);
        assert!((s.center_point().coords - c).norm() < 1e-9);
        assert!(s.rms < 1e-9);
    }

    #[test]
    fn robust_fit_ignores_a_displaced_patch_that_moves_the_plain_fit() {
        let mut pts: Vec<Point3<f64>> = (0..2000)
            .map(|i| {
                let t = 1.5 * ((i as f64 + 0.5) / 2000.0).sqrt();
                let p = i as f64 * 2.399;
                Point3::new(
                    25.0 * t.sin() * p.cos(),
                    25.0 * t.sin() * p.sin(),
                    -25.0 * t.cos(),
                )
            })
            .collect();
        for p in pts.iter_mut().filter(|p| p.x > 19.0) {
            *p = Point3::from(p.coords * 0.85); // a minority patch pulled 3.75 mm inwards
        }
        let plain = fit_sphere(&pts).unwrap();
        let robust = fit_sphere_robust(&pts).unwrap();
        assert!(
            (robust.radius - 25.0).abs() < 0.05,
            "robust {}",
            robust.radius
        );
        assert!((plain.radius - 25.0).abs() > 0.3, "plain {}", plain.radius);
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        assert_eq!(
            fit_sphere(&[Point3::origin(); 3]),
            Err(SphereFitError::TooFewPoints(3))
        );
        let plane: Vec<Point3<f64>> = (0..20)
            .map(|i| Point3::new(i as f64, (i * i % 7) as f64, 0.0))
            .collect();
        assert!(fit_sphere(&plane).is_err() || fit_sphere(&plane).unwrap().radius > 1e3);
    }
}
