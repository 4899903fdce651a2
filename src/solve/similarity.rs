//! Global similarity stage: before the deformation graph, the template is moved rigidly and
//! scaled (7 parameters) to minimise the same reprojection energy E_obs, with correspondences
//! recomputed between solves. This is what lets the method start from a pose that is off by
//! tens of degrees and centimetres.
//!
//! State x = (rotation vector of R, translation tau, log scale sigma); a vertex P moves to
//! c + tau + e^sigma R (P - c), c the template centroid. Steps compose on the left:
//! R <- Exp(d_omega) R, so the Jacobian is taken at d_omega = 0.

use super::lm::Problem;
use super::normal::Linearization;
use super::reprojection::{behind, reprojection, Reprojection};
use crate::correspond::Observation;
use crate::views::Camera;
use nalgebra::{Point3, Rotation3, Vector3};

/// Parameters of the full similarity: rotation vector, translation, log scale.
pub const SIM_PARAMS: usize = 7;

/// The similarity problem on fixed correspondences.
pub struct SimilarityProblem<'a> {
    /// The points at rest, mm.
    pub rest: &'a [Point3<f64>],
    /// The point the similarity turns and scales about.
    pub center: Point3<f64>,
    /// The views.
    pub cameras: &'a [Camera],
    /// The fixed correspondences.
    pub observations: &'a [Observation],
    /// Per view, pixels per mm at `center` (turns E_obs into mm).
    pub px_per_mm: Vec<f64>,
    /// Along-contour weight of the reprojection error (see `Observation::residual_frame`).
    pub tangential: f64,
    /// Solve for the rotation about `center` alone (3 parameters; translation and scale stay
    /// zero), as when the sphere is already known.
    pub rotation_only: bool,
}

/// Apply a similarity state to points.
pub fn apply_similarity(x: &[f64], center: &Point3<f64>, pts: &[Point3<f64>]) -> Vec<Point3<f64>> {
    let x = full_state(x);
    let r = Rotation3::new(Vector3::new(x[0], x[1], x[2]));
    let t = Vector3::new(x[3], x[4], x[5]);
    let s = x[6].exp();
    pts.iter()
        .map(|p| center + t + s * (r * (p - center)))
        .collect()
}

impl<'a> SimilarityProblem<'a> {
    /// The problem over `rest` (about its centroid) with correspondences `observations`.
    pub fn new(
        rest: &'a [Point3<f64>],
        cameras: &'a [Camera],
        observations: &'a [Observation],
    ) -> Self {
        let center = crate::geom::centroid(rest);
        let px_per_mm = cameras
            .iter()
            .map(|c| c.pixels_per_mm_at(&center))
            .collect();
        SimilarityProblem {
            rest,
            center,
            cameras,
            observations,
            px_per_mm,
            tangential: 1.0,
            rotation_only: false,
        }
    }
}

impl Problem for SimilarityProblem<'_> {
    fn block_size(&self) -> usize {
        if self.rotation_only {
            3
        } else {
            SIM_PARAMS
        }
    }
    fn n_blocks(&self) -> usize {
        1
    }
    fn linearize(&self, x: &[f64], jac: bool) -> Linearization {
        let n = self.block_size();
        let mut l = Linearization::new(n, 1);
        let x = full_state(x);
        let r = Rotation3::new(Vector3::new(x[0], x[1], x[2]));
        let t = Vector3::new(x[3], x[4], x[5]);
        let s = x[6].exp();
        for o in self.observations {
            let cam = &self.cameras[o.view];
            let k = o.weight.sqrt() / self.px_per_mm[o.view];
            let q = s * (r * (self.rest[o.vertex as usize] - self.center));
            let v = self.center + t + q;
            let Some(Reprojection {
                residual: res,
                jacobian: Some(jp),
            }) = reprojection(cam, &v, o, self.tangential, k, true)
            else {
                behind(&mut l);
                continue;
            };
            for row in 0..2 {
                if !jac {
                    l.push_residual(res[row]);
                    continue;
                }
                let jr = jp.row(row).transpose();
                // d v / d omega = -[q]x, so d r / d omega = q x jr.
                let dw = q.cross(&jr);
                let d = [dw.x, dw.y, dw.z, jr.x, jr.y, jr.z, jr.dot(&q)];
                l.push_row(res[row], &[(0, &d[..n])]);
            }
        }
        l
    }
    fn retract(&self, x: &[f64], d: &[f64]) -> Vec<f64> {
        let r = Rotation3::new(Vector3::new(d[0], d[1], d[2]))
            * Rotation3::new(Vector3::new(x[0], x[1], x[2]));
        let w = r.scaled_axis();
        let mut out = vec![w.x, w.y, w.z];
        out.extend(x.iter().zip(d).skip(3).map(|(a, b)| a + b));
        out
    }
}

/// A 3- (rotation only) or 7-parameter state as the full 7.
pub fn full_state(x: &[f64]) -> [f64; SIM_PARAMS] {
    let mut f = [0.0; SIM_PARAMS];
    for (a, b) in f.iter_mut().zip(x) {
        *a = *b;
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{simulated_views, XrayGeometry};
    use crate::solve::lm::{levenberg_marquardt, LmParams};
    use crate::template::hemisphere;

    #[test]
    fn recovers_a_known_similarity_from_exact_correspondences() {
        let m = hemisphere(26.0, 500);
        let cams = simulated_views(&XrayGeometry::default(), &Point3::origin());
        let truth = [0.2, -0.1, 0.15, 5.0, -8.0, 3.0, 0.2f64];
        let center = crate::geom::centroid(&m.vertices);
        let moved = apply_similarity(&truth, &center, &m.vertices);
        let obs: Vec<Observation> = (0..m.vertex_count())
            .step_by(5)
            .flat_map(|i| {
                let moved = &moved;
                let cams = &cams;
                (0..3).map(move |v| Observation {
                    view: v,
                    vertex: i as u32,
                    target: cams[v].project(&moved[i]).unwrap(),
                    weight: 1.0,
                    normal: nalgebra::Vector2::zeros(),
                })
            })
            .collect();
        let p = SimilarityProblem::new(&m.vertices, &cams, &obs);
        let (x, info) = levenberg_marquardt(
            &p,
            vec![0.0; 7],
            &LmParams {
                rel_tol: 1e-14,
                max_iterations: 100,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(info.costs.windows(2).all(|w| w[1] < w[0]));
        for (a, b) in x.iter().zip(&truth) {
            assert!((a - b).abs() < 1e-6, "{x:?}");
        }
    }
}
