//! Outlier rejection on aligned residuals: fit the best 2D similarity taking the model points onto
//! the observed ones (Umeyama), then drop pairs whose residual exceeds median + k * 1.4826 * MAD.

use nalgebra::{Matrix2, Point2, Vector2};

/// Residual of each (model, observed) pair after the least-squares similarity model -> observed.
pub fn similarity_residuals(pairs: &[(Point2<f64>, Point2<f64>)]) -> Vec<f64> {
    let n = pairs.len();
    if n == 0 {
        return Vec::new();
    }
    let mx = pairs.iter().map(|p| p.0.coords).sum::<Vector2<f64>>() / n as f64;
    let my = pairs.iter().map(|p| p.1.coords).sum::<Vector2<f64>>() / n as f64;
    let mut cov = Matrix2::zeros();
    let mut var = 0.0;
    for (x, y) in pairs {
        let (a, b) = (x.coords - mx, y.coords - my);
        cov += b * a.transpose();
        var += a.norm_squared();
    }
    // 2D similarity: y ~ s R x; with complex numbers the optimum is closed form.
    let c = cov[(0, 0)] + cov[(1, 1)];
    let s_ = cov[(1, 0)] - cov[(0, 1)];
    let (a, b) = if var > 0.0 {
        (c / var, s_ / var)
    } else {
        (1.0, 0.0)
    };
    pairs
        .iter()
        .map(|(x, y)| {
            let d = x.coords - mx;
            let pred = Vector2::new(a * d.x - b * d.y, b * d.x + a * d.y) + my;
            (y.coords - pred).norm()
        })
        .collect()
}

/// Inlier flags: residual <= median + k * 1.4826 * MAD (all inliers when MAD is 0).
pub fn mad_inliers(residuals: &[f64], k: f64) -> Vec<bool> {
    if residuals.is_empty() {
        return Vec::new();
    }
    let med = median(residuals.to_vec());
    let mad = median(residuals.iter().map(|r| (r - med).abs()).collect());
    if mad <= 0.0 {
        return vec![true; residuals.len()];
    }
    let limit = med + k * 1.4826 * mad;
    residuals.iter().map(|r| *r <= limit).collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn similarity_residuals_vanish_for_an_exact_similarity_and_flag_an_outlier() {
        let xs: Vec<Point2<f64>> = (0..30)
            .map(|i| Point2::new(i as f64, ((i * i) % 7) as f64))
            .collect();
        let mut pairs: Vec<(Point2<f64>, Point2<f64>)> = xs
            .iter()
            .map(|p| {
                (
                    *p,
                    Point2::new(
                        2.0 * (0.6 * p.x - 0.8 * p.y) + 3.0,
                        2.0 * (0.8 * p.x + 0.6 * p.y) - 1.0,
                    ),
                )
            })
            .collect();
        assert!(similarity_residuals(&pairs).iter().all(|r| *r < 1e-9));
        // Small noise everywhere, one gross outlier.
        for (i, p) in pairs.iter_mut().enumerate() {
            p.1.x += 0.1 * ((i % 3) as f64 - 1.0);
        }
        pairs[7].1.y += 25.0;
        let keep = mad_inliers(&similarity_residuals(&pairs), 3.0);
        assert!(!keep[7]);
        assert!(keep.iter().filter(|k| **k).count() >= 27);
    }
}
