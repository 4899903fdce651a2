//! The population prior the reconstruction uses: the mean deviation field of the training
//! acetabula and its principal modes, looked up at any direction.

use super::field::{grid, kernel, kernel_reach, GRID_POINTS, KERNEL_DEG, MIN_WEIGHT};
use nalgebra::{DMatrix, Vector3};

/// Most modes a prior can carry (the sphere block's free entries in the deformation solve).
pub const MAX_MODES: usize = 8;

/// Resolution of the lookup table, degrees (polar angle from +z by azimuth).
const TABLE_DEG: f64 = 2.0;

/// Mean shape and principal modes of the acetabulum's deviation from its sphere, in the prior's
/// frame (body axes, every hip opening towards -x).
#[derive(Clone, PartialEq)]
pub struct ShapePrior {
    /// What it was learned from, for people (names of the meshes).
    pub learned_from: Vec<String>,
    /// Mean relative radial deviation per grid direction (0 where no training mesh reaches).
    pub mean: Vec<f64>,
    /// Principal modes (unit vectors over the grid), largest first.
    pub modes: Vec<Vec<f64>>,
    /// SD of each mode's coefficient over the training meshes.
    pub mode_sd: Vec<f64>,
    /// Share of the training meshes that reach each grid direction (0 to 1).
    pub coverage: Vec<f64>,
    /// Lookup table: (mean, modes..., coverage) per (polar, azimuth) cell corner.
    table: Vec<f64>,
}

impl std::fmt::Debug for ShapePrior {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShapePrior")
            .field("meshes", &self.learned_from.len())
            .field("mode_sd", &self.mode_sd)
            .finish_non_exhaustive()
    }
}

/// Why a prior cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PriorError {
    /// Too few training meshes for the modes asked for.
    #[error("a prior with {modes} mode(s) needs at least {need} training meshes, got {got}")]
    TooFewMeshes {
        /// Modes asked for.
        modes: usize,
        /// Meshes needed.
        need: usize,
        /// Meshes given.
        got: usize,
    },
    /// More modes than the solve can carry.
    #[error("at most {MAX_MODES} modes, asked for {0}")]
    TooManyModes(usize),
    /// A field has the wrong length or a value that is not finite.
    #[error("the field of {name} is not a deviation field on {GRID_POINTS} directions: {reason}")]
    BadField {
        /// The training mesh.
        name: String,
        /// Why.
        reason: String,
    },
}

/// Fewest training meshes a prior with `modes` modes is learned from.
pub fn meshes_needed(modes: usize) -> usize {
    if modes == 0 {
        1
    } else {
        modes + 2
    }
}

impl ShapePrior {
    /// The prior of the fields `fields` (name, deviation per grid direction, None where the mesh
    /// does not reach) with `modes` principal modes.
    pub fn learn(fields: &[(String, Vec<Option<f64>>)], modes: usize) -> Result<Self, PriorError> {
        if modes > MAX_MODES {
            return Err(PriorError::TooManyModes(modes));
        }
        let need = meshes_needed(modes);
        if fields.len() < need {
            return Err(PriorError::TooFewMeshes {
                modes,
                need,
                got: fields.len(),
            });
        }
        for (name, f) in fields {
            if f.len() != GRID_POINTS {
                return Err(PriorError::BadField {
                    name: name.clone(),
                    reason: format!("{} values", f.len()),
                });
            }
            if let Some(v) = f.iter().flatten().find(|v| !v.is_finite() || v.abs() > 1.0) {
                return Err(PriorError::BadField {
                    name: name.clone(),
                    reason: format!("deviation {v} (must be finite, within +-1 of the radius)"),
                });
            }
        }
        let coverage: Vec<f64> = (0..GRID_POINTS)
            .map(|g| {
                fields.iter().filter(|(_, f)| f[g].is_some()).count() as f64 / fields.len() as f64
            })
            .collect();
        let mean: Vec<f64> = (0..GRID_POINTS)
            .map(|g| {
                let (s, n) = fields
                    .iter()
                    .filter_map(|(_, f)| f[g])
                    .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
                if n == 0 {
                    0.0
                } else {
                    s / n as f64
                }
            })
            .collect();
        let (modes, mode_sd) = if modes == 0 {
            (Vec::new(), Vec::new())
        } else {
            // Centred fields (a direction a mesh does not reach takes the mean), one row each.
            let x = DMatrix::from_fn(fields.len(), GRID_POINTS, |i, g| {
                fields[i].1[g].map_or(0.0, |v| v - mean[g])
            });
            let svd = x.svd(false, true);
            let vt = svd.v_t.as_ref().ok_or_else(|| PriorError::BadField {
                name: "the training set".into(),
                reason: "no singular vectors".into(),
            })?;
            let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
            order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
            let dof = (fields.len() - 1) as f64;
            let mut ms = Vec::new();
            let mut sds = Vec::new();
            for &k in order.iter().take(modes) {
                let mut m: Vec<f64> = vt.row(k).iter().copied().collect();
                // A mode's sign is arbitrary: make its largest entry positive, so that the same
                // training set always gives the same prior.
                let big = m
                    .iter()
                    .copied()
                    .fold(0.0f64, |a, v| if v.abs() > a.abs() { v } else { a });
                if big < 0.0 {
                    m.iter_mut().for_each(|v| *v = -*v);
                }
                ms.push(m);
                sds.push((svd.singular_values[k] / dof.sqrt()).max(1e-9));
            }
            (ms, sds)
        };
        let mut prior = ShapePrior {
            learned_from: fields.iter().map(|(n, _)| n.clone()).collect(),
            mean,
            modes,
            mode_sd,
            coverage,
            table: Vec::new(),
        };
        prior.table = prior.build_table();
        Ok(prior)
    }

    /// Number of modes.
    pub fn mode_count(&self) -> usize {
        self.modes.len()
    }

    fn table_dims() -> (usize, usize) {
        let polar = (180.0 / TABLE_DEG).round() as usize + 1;
        let azimuth = (360.0 / TABLE_DEG).round() as usize;
        (polar, azimuth)
    }

    fn cell_direction(i: usize, j: usize) -> Vector3<f64> {
        let t = (i as f64 * TABLE_DEG).to_radians();
        let p = (j as f64 * TABLE_DEG).to_radians();
        Vector3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    /// Entries per table corner: the mean, the modes, the coverage.
    fn per_corner(&self) -> usize {
        2 + self.modes.len()
    }

    /// The kernel-smoothed (mean, modes..., coverage) at every table corner.
    fn build_table(&self) -> Vec<f64> {
        let (np, na) = Self::table_dims();
        let per = self.per_corner();
        let last = per - 1;
        let g = grid(GRID_POINTS);
        let sigma = KERNEL_DEG.to_radians();
        let reach = kernel_reach(sigma);
        let mut table = vec![0.0; np * na * per];
        for i in 0..np {
            for j in 0..na {
                let u = Self::cell_direction(i, j);
                let mut w = 0.0;
                let mut acc = vec![0.0; per];
                for (k, gk) in g.iter().enumerate() {
                    let cos = gk.dot(&u);
                    if cos < reach {
                        continue;
                    }
                    let kw = kernel(cos, sigma);
                    w += kw;
                    acc[0] += kw * self.mean[k];
                    for (a, m) in acc[1..last].iter_mut().zip(&self.modes) {
                        *a += kw * m[k];
                    }
                    acc[last] += kw * self.coverage[k];
                }
                let at = (i * na + j) * per;
                if w >= MIN_WEIGHT {
                    for (t, a) in table[at..at + per].iter_mut().zip(&acc) {
                        *t = a / w;
                    }
                }
            }
        }
        table
    }

    /// The mean deviation and the modes' values at unit direction `u` (prior frame), written to
    /// `modes` (its first `mode_count()` entries): bilinear in the lookup table.
    pub fn at(&self, u: &Vector3<f64>, modes: &mut [f64; MAX_MODES]) -> f64 {
        let value = self.lookup(u);
        for (c, m) in modes.iter_mut().enumerate().take(self.modes.len()) {
            *m = value(1 + c);
        }
        value(0)
    }

    /// The share of the training meshes whose surface reaches unit direction `u` (prior frame),
    /// kernel-smoothed: about 1 inside the region every training acetabulum covers, 0 beyond
    /// any of them.
    pub fn coverage_at(&self, u: &Vector3<f64>) -> f64 {
        self.lookup(u)(self.per_corner() - 1)
    }

    /// Bilinear interpolation of the table's corners around `u`, one entry at a time.
    fn lookup(&self, u: &Vector3<f64>) -> impl Fn(usize) -> f64 + '_ {
        let (np, na) = Self::table_dims();
        let per = self.per_corner();
        let polar = u.z.clamp(-1.0, 1.0).acos().to_degrees() / TABLE_DEG;
        let az = u.y.atan2(u.x).to_degrees().rem_euclid(360.0) / TABLE_DEG;
        let i0 = (polar.floor() as usize).min(np - 2);
        let fi = (polar - i0 as f64).clamp(0.0, 1.0);
        let j0 = (az.floor() as usize) % na;
        let fj = (az - az.floor()).clamp(0.0, 1.0);
        let j1 = (j0 + 1) % na;
        let corner = move |i: usize, j: usize, c: usize| self.table[(i * na + j) * per + c];
        move |c: usize| {
            (1.0 - fi) * ((1.0 - fj) * corner(i0, j0, c) + fj * corner(i0, j1, c))
                + fi * ((1.0 - fj) * corner(i0 + 1, j0, c) + fj * corner(i0 + 1, j1, c))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::fit_sphere;
    use crate::prior::field::deviation_field;
    use crate::template::hemisphere;
    use nalgebra::Point3;

    /// A cap of radius 25 opening to -x, flattened by `flat` along y.
    fn field_of(flat: f64) -> Vec<Option<f64>> {
        let v: Vec<Point3<f64>> = hemisphere(25.0, 1500)
            .vertices
            .iter()
            .map(|p| Point3::new(-p.z, p.y * (1.0 - flat), p.x))
            .collect();
        deviation_field(&v, &fit_sphere(&v).unwrap()).0
    }

    fn training() -> Vec<(String, Vec<Option<f64>>)> {
        [0.02, 0.05, 0.08, 0.03, 0.06]
            .iter()
            .enumerate()
            .map(|(i, f)| (format!("m{i}"), field_of(*f)))
            .collect()
    }

    #[test]
    fn the_mean_is_the_training_fields_mean_and_its_first_mode_is_the_flattening() {
        let train = training();
        let p = ShapePrior::learn(&train, 2).unwrap();
        let mid = ShapePrior::learn(&[("f".into(), field_of(0.048))], 0).unwrap();
        let mut m = [0.0; MAX_MODES];
        let front = Vector3::new(0.3, 0.95, 0.0).normalize();
        let top = Vector3::new(0.3, 0.0, 0.95).normalize();
        for u in [front, top] {
            let (a, b) = (p.at(&u, &mut m), mid.at(&u, &mut [0.0; MAX_MODES]));
            assert!((a - b).abs() < 2e-3, "{a} {b}");
        }
        // The flattening varies; the first mode carries nearly all of the spread.
        assert!(p.mode_sd[0] > 10.0 * p.mode_sd[1], "{:?}", p.mode_sd);
        p.at(&front, &mut m);
        let f = m[0];
        p.at(&top, &mut m);
        assert!((f - m[0]).abs() > 1e-3, "{f} {}", m[0]);
    }

    #[test]
    fn a_prior_of_other_shapes_is_told_apart_from_the_right_one() {
        let p = ShapePrior::learn(&training(), 0).unwrap();
        let round = ShapePrior::learn(&[("r".into(), field_of(0.0))], 0).unwrap();
        let front = Vector3::new(0.3, 0.95, 0.0).normalize();
        let mut m = [0.0; MAX_MODES];
        assert!((p.at(&front, &mut m) - round.at(&front, &mut m)).abs() > 5e-3);
    }

    #[test]
    fn bad_training_sets_are_refused_with_the_reason() {
        let train = training();
        assert!(matches!(
            ShapePrior::learn(&train[..2], 2),
            Err(PriorError::TooFewMeshes { .. })
        ));
        assert!(matches!(
            ShapePrior::learn(&train, 9),
            Err(PriorError::TooManyModes(9))
        ));
        let mut bad = train.clone();
        bad[1].1[3] = Some(f64::NAN);
        let e = ShapePrior::learn(&bad, 1).unwrap_err().to_string();
        assert!(e.contains("m1") && e.contains("NaN"), "{e}");
        bad[1].1.pop();
        assert!(ShapePrior::learn(&bad, 1).is_err());
    }

    #[test]
    fn coverage_is_the_share_of_training_meshes_reaching_a_direction() {
        // Three of field_of's caps (in the prior's frame they reach the +x half) and one
        // turned to reach the +z half: a direction in both halves is reached by all four, one
        // in the caps' half only by three, one in neither by none.
        let cap = field_of(0.0);
        let turned: Vec<Point3<f64>> = hemisphere(25.0, 1500)
            .vertices
            .iter()
            .map(|p| Point3::new(p.x, p.y, -p.z))
            .collect();
        let other = deviation_field(&turned, &fit_sphere(&turned).unwrap()).0;
        let set = vec![
            ("a".to_string(), cap.clone()),
            ("b".to_string(), cap.clone()),
            ("c".to_string(), cap),
            ("d".to_string(), other),
        ];
        let p = ShapePrior::learn(&set, 0).unwrap();
        let caps_only = Vector3::new(1.0, 0.0, -0.5).normalize();
        let both = Vector3::new(1.0, 0.0, 1.0).normalize();
        let neither = Vector3::new(-1.0, 0.0, -0.5).normalize();
        let at = |p: &ShapePrior, u| p.coverage_at(u);
        assert!(
            (at(&p, &caps_only) - 0.75).abs() < 0.02,
            "{}",
            at(&p, &caps_only)
        );
        assert!((at(&p, &both) - 1.0).abs() < 0.02, "{}", at(&p, &both));
        assert!(at(&p, &neither) < 0.02, "{}", at(&p, &neither));
        // Companion: the turned cap's own prior covers other directions.
        let q = ShapePrior::learn(&set[3..], 0).unwrap();
        assert!(at(&q, &caps_only) < 0.02 && at(&q, &both) > 0.98);
    }

    #[test]
    fn the_same_training_set_gives_the_same_prior() {
        assert_eq!(
            ShapePrior::learn(&training(), 2).unwrap(),
            ShapePrior::learn(&training(), 2).unwrap()
        );
    }
}
