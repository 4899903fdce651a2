//! Summary statistics, each written once: the centroid of points, the mean and SD of values, and
//! a quantile of sorted values.

use nalgebra::{Point3, Vector3};

/// Centroid of a point set (the origin for none).
pub fn centroid(p: &[Point3<f64>]) -> Point3<f64> {
    Point3::from(p.iter().map(|v| v.coords).sum::<Vector3<f64>>() / p.len().max(1) as f64)
}

/// The opening axis of a cup-shaped point set on a sphere centred at `center`: from the points'
/// centroid through the centre (the z axis when they coincide).
pub fn opening_axis(p: &[Point3<f64>], center: &Point3<f64>) -> nalgebra::Unit<Vector3<f64>> {
    nalgebra::Unit::try_new(center - centroid(p), 1e-9).unwrap_or(Vector3::z_axis())
}

/// Mean of the values (NaN for none).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.iter().sum::<f64>() / v.len() as f64
}

/// Mean and SD of the values: the SD divides by n when `sample` is false (the spread of these
/// values themselves: errors over a surface, runs of a study) and by n - 1 when true (the
/// estimate of the spread of the distribution they were drawn from: resamples). NaN for none;
/// a sample SD of one value is 0.
pub fn mean_sd(v: &[f64], sample: bool) -> (f64, f64) {
    let m = mean(v);
    if v.is_empty() {
        return (m, f64::NAN);
    }
    let n = v.len() as f64;
    let denominator = if sample { (n - 1.0).max(1.0) } else { n };
    let ss = v.iter().map(|x| (x - m).powi(2)).sum::<f64>();
    (m, (ss / denominator).sqrt())
}

/// The `f` quantile (0..=1) of values sorted ascending, by the nearest rank: the value at
/// round(f * (n - 1)). NaN for none.
pub fn quantile_sorted(sorted: &[f64], f: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = (f * (sorted.len() - 1) as f64).round() as usize;
    sorted[k.min(sorted.len() - 1)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimators_on_known_values() {
        let v = [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0];
        assert_eq!(mean_sd(&v, false), (5.0, 2.0));
        let (_, s) = mean_sd(&v, true);
        assert!((s - (32.0f64 / 7.0).sqrt()).abs() < 1e-15);
        assert_eq!(quantile_sorted(&v, 0.5), 5.0); // round(3.5) = 4
        assert_eq!(quantile_sorted(&v, 1.0), 9.0);
        assert_eq!(
            centroid(&[Point3::new(0.0, 0.0, 0.0), Point3::new(2.0, 4.0, 6.0)]),
            Point3::new(1.0, 2.0, 3.0)
        );
        assert!(mean(&[]).is_nan() && quantile_sorted(&[], 0.5).is_nan());
        // Companion: a wrong answer is told apart.
        assert_ne!(mean_sd(&v, true), (5.0, 2.0));
    }
}
