//! Sphere fit: algebraic (linear least squares on |p|^2 = 2 c.p + d), then geometric refinement
//! (Gauss-Newton on sum (|p - c| - r)^2).

use nalgebra::{Matrix4, Point3, Vector3, Vector4};

/// A sphere in mm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Sphere {
    pub center: [f64; 3],
    pub radius: f64,
    /// RMS of |p - c| - r over the fitted points.
    pub rms: f64,
}

impl Sphere {
    pub fn diameter(&self) -> f64 {
        2.0 * self.radius
    }
    pub fn center_point(&self) -> Point3<f64> {
        Point3::new(self.center[0], self.center[1], self.center[2])
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SphereFitError {
    #[error("a sphere needs at least 4 points, got {0}")]
    TooFewPoints(usize),
    #[error("the points are degenerate (coplanar or coincident); no unique sphere")]
    Degenerate,
}

/// Fit a sphere to points.
pub fn fit_sphere(points: &[Point3<f64>]) -> Result<Sphere, SphereFitError> {
    if points.len() < 4 {
        return Err(SphereFitError::TooFewPoints(points.len()));
    }
    // Algebraic: [2x 2y 2z 1] [c; d] = |p|^2, centred for conditioning.
    let mean = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / points.len() as f64;
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    for p in points {
        let q = p.coords - mean;
        let row = Vector4::new(2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0);
        ata += row * row.transpose();
        atb += row * q.norm_squared();
    }
    let sol = ata.cholesky().ok_or(SphereFitError::Degenerate)?.solve(&atb);
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
        for p in points {
            let d = p.coords - mean - c;
            let n = d.norm().max(1e-12);
            let res = n - r;
            let j = Vector4::new(-d.x / n, -d.y / n, -d.z / n, -1.0);
            jtj += j * j.transpose();
            jtr += j * res;
        }
        let Some(ch) = jtj.cholesky() else { break };
        let step = -ch.solve(&jtr);
        c += Vector3::new(step[0], step[1], step[2]);
        r += step[3];
        if step.norm() < 1e-12 * (1.0 + r) {
            break;
        }
    }
    let rms = (points.iter().map(|p| ((p.coords - mean - c).norm() - r).powi(2)).sum::<f64>() / points.len() as f64).sqrt();
    let center = c + mean;
    if !(r > 0.0 && r.is_finite() && center.iter().all(|v| v.is_finite())) {
        return Err(SphereFitError::Degenerate);
    }
    Ok(Sphere { center: [center.x, center.y, center.z], radius: r.abs(), rms })
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
                Point3::from(c + 27.5 * Vector3::new(t.sin() * p.cos(), t.sin() * p.sin(), -t.cos()))
            })
            .collect();
        let s = fit_sphere(&pts).unwrap();
        assert!((s.radius - 27.5).abs() < 1e-9, "{}", s.radius);
        assert!((s.center_point().coords - c).norm() < 1e-9);
        assert!(s.rms < 1e-9);
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        assert_eq!(fit_sphere(&[Point3::origin(); 3]), Err(SphereFitError::TooFewPoints(3)));
        let plane: Vec<Point3<f64>> = (0..20).map(|i| Point3::new(i as f64, (i * i % 7) as f64, 0.0)).collect();
        assert!(fit_sphere(&plane).is_err() || fit_sphere(&plane).unwrap().radius > 1e3);
    }
}
