//! The embedded-deformation energy w_rot E_rot + w_reg E_reg + w_obs E_obs as residuals with
//! analytic Jacobians (Sumner 2007, eqs. 2-4, with E_obs the reprojection error of corresponded
//! vertices).
//!
//! Units: E_reg residuals are millimetres; E_obs residuals are pixels divided by the view's
//! pixels-per-millimetre at the object (5500 / 900 = 6.1 in the simulated set-up), so they are
//! millimetres at the object too and the weights compare like with like. E_rot is unitless.
//! The method's authors (and ElasticFusion) use w_rot = 1, w_reg = 10, w_obs = 100. With E_obs in
//! millimetres at the object, w_reg = 10 can let the silhouettes pull the surface into shapes the
//! three views cannot confirm: on the eight shared acetabula (level 1, seed 1) 4 of 8 end under
//! 1 mm MAE with w_reg = 10 and 6 of 8 with w_reg = 100; on the phantom the two are alike. The
//! defaults stay the published ones; studies can raise `EdWeights::reg`.
//!
//! A silhouette point may slide along the outline as the shape changes, so the reprojection
//! residual is measured mostly across the observed contour (point to tangent line), with weight
//! `tangential` = 0.1 along it (see `Observation::residual_frame`).

use super::graph::{DeformationGraph, NODE_PARAMS};
use super::lm::Problem;
use super::normal::Linearization;
use super::reprojection::{behind, reprojection, Reprojection};
use crate::correspond::Observation;
use crate::views::Camera;
use nalgebra::Point3;

/// Energy weights.
#[derive(Clone, Debug, PartialEq)]
pub struct EdWeights {
    /// w_rot, on E_rot (the graph's affine maps near rotations).
    pub rot: f64,
    /// w_reg, on E_reg (neighbouring nodes agree).
    pub reg: f64,
    /// w_obs, on E_obs (projections onto their targets).
    pub obs: f64,
    /// Weight of the reprojection error along the observed contour relative to across it
    /// (default 0.1). A reconstruction sets it per method: `ReconParams::tangential`.
    pub tangential: f64,
}

impl Default for EdWeights {
    fn default() -> Self {
        EdWeights {
            rot: 1.0,
            reg: 10.0,
            obs: 100.0,
            tangential: 0.1,
        }
    }
}

/// The ED problem over a graph, the cameras and fixed correspondences.
pub struct EdProblem<'a> {
    /// The graph being solved for.
    pub graph: &'a DeformationGraph,
    /// The views.
    pub cameras: &'a [Camera],
    /// The fixed correspondences.
    pub observations: &'a [Observation],
    /// The energy's weights.
    pub weights: EdWeights,
    /// Pixels per millimetre per view (divides the reprojection residual).
    pub px_per_mm: Vec<f64>,
    /// Optional sphere prior (see `SpherePrior`).
    pub sphere: Option<SpherePrior>,
}

/// E_sph = sum_i (|v_i - S| - R)^2 over the listed vertices, the sphere (S, R) solved with the
/// deformation: one extra parameter block after the nodes' (S then R, its other 8 entries held
/// at zero). An acetabulum is close to a sphere (the cup that replaces it is one), and three
/// views about one axis see its walls only edge-on; this term keeps the deformation from
/// bending the walls where no outline watches them, while the sphere itself may move and grow.
#[derive(Clone, Debug, PartialEq)]
pub struct SpherePrior {
    /// Weight per vertex (mm^-2 like E_reg's).
    pub weight: f64,
    /// The vertices that carry the prior.
    pub vertices: Vec<u32>,
    /// The population's shape around the sphere (None: the bare sphere).
    pub shape: Option<ShapeTerms>,
}

/// A learned shape around the sphere prior's sphere (`prior::ShapePrior` looked up at each
/// listed vertex's direction): vertex `vertices[n]`'s target distance from the centre is
/// `R (1 + mean[n] + sum_k b_k modes[k][n])`, the mode coefficients b_k solved with the sphere
/// (the sphere block's entries 4, 5, ...) under a Gaussian prior (rows `b_k / sd[k]`).
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeTerms {
    /// Mean relative deviation at each listed vertex.
    pub mean: Vec<f64>,
    /// Each mode's value at each listed vertex (at most 8 modes).
    pub modes: Vec<Vec<f64>>,
    /// Each mode coefficient's SD.
    pub sd: Vec<f64>,
}

impl ShapeTerms {
    /// The relative target radius 1 + mean + sum_k b_k modes[k] of listed vertex `n`.
    fn scale(&self, n: usize, b: &[f64]) -> f64 {
        1.0 + self.mean[n]
            + self
                .modes
                .iter()
                .zip(b)
                .map(|(m, bk)| m[n] * bk)
                .sum::<f64>()
    }
}

/// Weight of the rows that hold the sphere block's unused entries at zero.
const UNUSED_HOLD: f64 = 1e-3;

impl EdProblem<'_> {
    /// The parameter vector to start from: identity nodes, then the sphere block at `sphere`
    /// (centre, radius) when the prior is on.
    pub fn start(&self, sphere: (Point3<f64>, f64)) -> Vec<f64> {
        let mut x = self.graph.identity();
        if self.sphere.is_some() {
            let mut b = [0.0; NODE_PARAMS];
            b[..3].copy_from_slice(sphere.0.coords.as_slice());
            b[3] = sphere.1;
            x.extend_from_slice(&b);
        }
        x
    }

    fn sphere_rows(&self, x: &[f64], jac: bool, l: &mut Linearization) {
        let Some(sp) = &self.sphere else {
            return;
        };
        let g = self.graph;
        let sb = g.node_count();
        let o = sb * NODE_PARAMS;
        let c = Point3::new(x[o], x[o + 1], x[o + 2]);
        let rad = x[o + 3];
        let ws = sp.weight.sqrt();
        let shape = sp.shape.as_ref();
        let n_modes = shape.map_or(0, |s| s.modes.len().min(NODE_PARAMS - 4));
        let coef = &x[o + 4..o + 4 + n_modes];
        let mut blocks: Vec<(u32, [f64; NODE_PARAMS])> = Vec::new();
        for (at, &i) in sp.vertices.iter().enumerate() {
            let i = i as usize;
            if i >= g.rest.len() {
                continue;
            }
            let scale = shape.map_or(1.0, |s| s.scale(at, coef));
            let v = g.deform_vertex(x, i);
            let d = v - c;
            let len = d.norm();
            let r = ws * (len - rad * scale);
            if !jac {
                l.push_residual(r);
                continue;
            }
            let n = if len > 1e-12 {
                d / len
            } else {
                nalgebra::Vector3::zeros()
            };
            blocks.clear();
            let p = g.rest[i];
            for &(j, w) in &g.weights[i] {
                let dp = p - g.nodes[j as usize];
                let mut b = [0.0; NODE_PARAMS];
                for row in 0..3 {
                    let f = ws * n[row] * w;
                    for col in 0..3 {
                        b[row * 3 + col] = f * dp[col];
                    }
                    b[9 + row] = f;
                }
                blocks.push((j, b));
            }
            let mut b = [0.0; NODE_PARAMS];
            b[0] = -ws * n.x;
            b[1] = -ws * n.y;
            b[2] = -ws * n.z;
            b[3] = -ws * scale;
            if let Some(s) = shape {
                for k in 0..n_modes {
                    b[4 + k] = -ws * rad * s.modes[k][at];
                }
            }
            blocks.push((sb as u32, b));
            let refs: Vec<(u32, &[f64])> = blocks.iter().map(|(j, b)| (*j, &b[..])).collect();
            l.push_row(r, &refs);
        }
        for k in 4..NODE_PARAMS {
            // A mode's coefficient under its Gaussian prior; the entries no mode uses held at 0.
            let hold = match shape {
                Some(s) if k - 4 < n_modes => 1.0 / s.sd[k - 4],
                _ => UNUSED_HOLD,
            };
            let r = hold * x[o + k];
            if jac {
                let mut b = [0.0; NODE_PARAMS];
                b[k] = hold;
                l.push_row(r, &[(sb as u32, &b)]);
            } else {
                l.push_residual(r);
            }
        }
    }
}

impl<'a> EdProblem<'a> {
    /// The problem over `graph` with correspondences `observations` in `cameras`.
    pub fn new(
        graph: &'a DeformationGraph,
        cameras: &'a [Camera],
        observations: &'a [Observation],
        weights: EdWeights,
    ) -> Self {
        let n = graph.rest.len().max(1) as f64;
        let centroid = Point3::from(
            graph
                .rest
                .iter()
                .map(|p| p.coords)
                .sum::<nalgebra::Vector3<f64>>()
                / n,
        );
        let px_per_mm = cameras
            .iter()
            .map(|c| c.pixels_per_mm_at(&centroid))
            .collect();
        EdProblem {
            graph,
            cameras,
            observations,
            weights,
            px_per_mm,
            sphere: None,
        }
    }
}

impl Problem for EdProblem<'_> {
    fn block_size(&self) -> usize {
        NODE_PARAMS
    }

    fn n_blocks(&self) -> usize {
        self.graph.node_count() + usize::from(self.sphere.is_some())
    }

    fn linearize(&self, x: &[f64], jac: bool) -> Linearization {
        let g = self.graph;
        let mut l = Linearization::new(NODE_PARAMS, self.n_blocks());
        // E_rot: columns c1, c2, c3 of A_j orthonormal.
        let wr = self.weights.rot.sqrt();
        for j in 0..g.node_count() {
            let a = &x[j * NODE_PARAMS..j * NODE_PARAMS + 9];
            let col = |c: usize| [a[c], a[3 + c], a[6 + c]];
            let cols = [col(0), col(1), col(2)];
            for (c1, c2) in [(0, 1), (0, 2), (1, 2), (0, 0), (1, 1), (2, 2)] {
                let dot: f64 = (0..3).map(|r| cols[c1][r] * cols[c2][r]).sum();
                let r = wr * (dot - if c1 == c2 { 1.0 } else { 0.0 });
                if jac {
                    let mut d = [0.0; NODE_PARAMS];
                    for row in 0..3 {
                        d[row * 3 + c1] += wr * cols[c2][row];
                        d[row * 3 + c2] += wr * cols[c1][row];
                    }
                    l.push_row(r, &[(j as u32, &d)]);
                } else {
                    l.push_residual(r);
                }
            }
        }
        // E_reg: node j's map applied to neighbour k should agree with k's own position.
        let wg = self.weights.reg.sqrt();
        for j in 0..g.node_count() {
            let (aj, tj) = DeformationGraph::affine(x, j);
            for &k in &g.node_neighbours[j] {
                let k = k as usize;
                let (_, tk) = DeformationGraph::affine(x, k);
                let d = g.nodes[k] - g.nodes[j];
                let e = aj * d + g.nodes[j].coords + tj - g.nodes[k].coords - tk;
                for row in 0..3 {
                    if jac {
                        let mut dj = [0.0; NODE_PARAMS];
                        for c in 0..3 {
                            dj[row * 3 + c] = wg * d[c];
                        }
                        dj[9 + row] = wg;
                        let mut dk = [0.0; NODE_PARAMS];
                        dk[9 + row] = -wg;
                        l.push_row(wg * e[row], &[(j as u32, &dj), (k as u32, &dk)]);
                    } else {
                        l.push_residual(wg * e[row]);
                    }
                }
            }
        }
        // E_obs: reprojection of corresponded vertices, in mm at the object.
        let wo = self.weights.obs.sqrt();
        let mut blocks: Vec<(u32, [f64; NODE_PARAMS])> = Vec::new();
        for o in self.observations {
            let cam = &self.cameras[o.view];
            let s = wo * o.weight.sqrt() / self.px_per_mm[o.view];
            let v = g.deform_vertex(x, o.vertex as usize);
            let Some(Reprojection {
                residual: res,
                jacobian,
            }) = reprojection(cam, &v, o, self.weights.tangential, s, jac)
            else {
                behind(&mut l);
                continue;
            };
            match jacobian {
                None => {
                    l.push_residual(res.x);
                    l.push_residual(res.y);
                }
                Some(jp) => {
                    for row in 0..2 {
                        blocks.clear();
                        let p = g.rest[o.vertex as usize];
                        for &(j, w) in &g.weights[o.vertex as usize] {
                            let d = p - g.nodes[j as usize];
                            let mut b = [0.0; NODE_PARAMS];
                            for r in 0..3 {
                                let f = jp[(row, r)] * w;
                                for c in 0..3 {
                                    b[r * 3 + c] = f * d[c];
                                }
                                b[9 + r] = f;
                            }
                            blocks.push((j, b));
                        }
                        let refs: Vec<(u32, &[f64])> =
                            blocks.iter().map(|(j, b)| (*j, &b[..])).collect();
                        l.push_row(res[row], &refs);
                    }
                }
            }
        }
        self.sphere_rows(x, jac, &mut l);
        l
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{simulated_views, XrayGeometry};
    use crate::solve::graph::GraphParams;
    use crate::solve::lm::{levenberg_marquardt, LmParams};
    use crate::template::hemisphere;
    use nalgebra::Vector2;
    use rand::{RngExt, SeedableRng};

    fn setup() -> (DeformationGraph, Vec<Camera>, Vec<Observation>) {
        let m = hemisphere(26.0, 600);
        let g = DeformationGraph::new(
            &m,
            &GraphParams {
                nodes: 30,
                ..Default::default()
            },
        );
        let cams = simulated_views(&XrayGeometry::default(), &Point3::origin());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let obs = (0..60)
            .map(|i| {
                let view = i % 3;
                let vertex = rng.random_range(0..m.vertex_count() as u32);
                // Targets from a slightly scaled and shifted copy: a deformation the graph can reach.
                let moved = Point3::from(
                    m.vertices[vertex as usize].coords * 1.05
                        + nalgebra::Vector3::new(1.0, -2.0, 0.5),
                );
                Observation {
                    view,
                    vertex,
                    target: cams[view].project(&moved).unwrap(),
                    weight: 1.0,
                    normal: Vector2::zeros(),
                }
            })
            .collect();
        (g, cams, obs)
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let (g, cams, obs) = setup();
        let p = EdProblem::new(&g, &cams, &obs, EdWeights::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let x: Vec<f64> = g
            .identity()
            .iter()
            .map(|v| v + rng.random_range(-0.05..0.05))
            .collect();
        let j = p.linearize(&x, true).dense_jacobian();
        let worst = worst_fd_error(&p, &x, &j);
        assert!(worst < 1e-5, "worst relative Jacobian error {worst}");
    }

    /// The problem with the sphere prior on every vertex, at a perturbed point.
    fn with_prior<'a>(
        g: &'a DeformationGraph,
        cams: &'a [Camera],
        obs: &'a [Observation],
    ) -> (EdProblem<'a>, Vec<f64>) {
        let mut p = EdProblem::new(g, cams, obs, EdWeights::default());
        p.sphere = Some(SpherePrior {
            weight: 0.3,
            vertices: (0..g.rest.len() as u32).collect(),
            shape: None,
        });
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let x: Vec<f64> = p
            .start((Point3::new(0.5, -0.3, 0.2), 25.0))
            .iter()
            .map(|v| v + rng.random_range(-0.05..0.05))
            .collect();
        (p, x)
    }

    fn worst_fd_error(p: &EdProblem, x: &[f64], j: &nalgebra::DMatrix<f64>) -> f64 {
        let r0 = p.linearize(x, false).r;
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for k in (0..x.len()).step_by(5).chain(x.len() - 12..x.len()) {
            let mut xp = x.to_vec();
            xp[k] += h;
            let mut xm = x.to_vec();
            xm[k] -= h;
            let (rp, rm) = (p.linearize(&xp, false).r, p.linearize(&xm, false).r);
            for row in 0..r0.len() {
                let fd = (rp[row] - rm[row]) / (2.0 * h);
                worst = worst.max((fd - j[(row, k)]).abs() / (1.0 + fd.abs()));
            }
        }
        worst
    }

    #[test]
    fn sphere_prior_jacobian_matches_finite_differences() {
        let (g, cams, obs) = setup();
        let (p, x) = with_prior(&g, &cams, &obs);
        assert_eq!(p.n_blocks(), g.node_count() + 1);
        let mut j = p.linearize(&x, true).dense_jacobian();
        assert_eq!(j.ncols(), x.len());
        assert!(worst_fd_error(&p, &x, &j) < 1e-5);
        // Companion: a 1 % error in the radius column of one prior row is caught.
        let row = j.nrows() - 9; // the last vertex's prior row
        let k = g.node_count() * NODE_PARAMS + 3;
        assert!(j[(row, k)].abs() > 0.1);
        j[(row, k)] *= 1.01;
        assert!(worst_fd_error(&p, &x, &j) > 1e-5);
    }

    /// Two modes and a mean that vary over the vertices, as a learned prior's do.
    fn shape_terms(g: &DeformationGraph) -> ShapeTerms {
        let n = g.rest.len();
        let wave = |f: f64| {
            (0..n)
                .map(|i| 0.03 * (f * i as f64).sin())
                .collect::<Vec<f64>>()
        };
        ShapeTerms {
            mean: wave(0.37),
            modes: vec![wave(0.11), wave(0.73)],
            sd: vec![0.8, 0.3],
        }
    }

    #[test]
    fn shape_prior_jacobian_matches_finite_differences() {
        let (g, cams, obs) = setup();
        let (mut p, mut x) = with_prior(&g, &cams, &obs);
        p.sphere.as_mut().unwrap().shape = Some(shape_terms(&g));
        let o = g.node_count() * NODE_PARAMS;
        x[o + 4] = 0.4;
        x[o + 5] = -0.2;
        let mut j = p.linearize(&x, true).dense_jacobian();
        assert!(worst_fd_error(&p, &x, &j) < 1e-5);
        // Companion: a 1 % error in one mode column of one prior row is caught.
        let row = j.nrows() - 9;
        assert!(j[(row, o + 5)].abs() > 1e-3, "{}", j[(row, o + 5)]);
        j[(row, o + 5)] *= 1.01;
        assert!(worst_fd_error(&p, &x, &j) > 1e-5);
    }

    #[test]
    fn shape_prior_is_zero_on_its_shape_and_not_on_the_bare_sphere() {
        let (g, cams, _) = setup();
        let (mut p, _) = with_prior(&g, &cams, &[]);
        let terms = shape_terms(&g);
        let cost = |p: &EdProblem, x: &[f64]| p.linearize(x, false).cost();
        let bare = p.start((Point3::origin(), 26.0));
        assert!(cost(&p, &bare) < 1e-12);
        p.sphere.as_mut().unwrap().shape = Some(terms.clone());
        assert!(cost(&p, &bare) > 1e-3, "{}", cost(&p, &bare));
        let mut on = ShapeTerms {
            mean: vec![0.0; terms.mean.len()],
            ..terms
        };
        on.modes[0] = vec![0.02; on.mean.len()];
        p.sphere.as_mut().unwrap().shape = Some(on);
        // Mode 0 constant 0.02 with b_0 = -1 gives scale 0.98: radius 26 / 0.98 fits exactly but
        // for the coefficient's own prior row (b / sd)^2.
        let mut x = p.start((Point3::origin(), 26.0 / 0.98));
        x[g.node_count() * NODE_PARAMS + 4] = -1.0;
        let c = cost(&p, &x);
        assert!((c - (1.0f64 / 0.8).powi(2)).abs() < 1e-9, "{c}");
    }

    #[test]
    fn sphere_prior_is_zero_on_its_sphere_and_not_off_it() {
        let (g, cams, _) = setup();
        // hemisphere(26.0, ..) is centred at the origin with radius 26.
        let (p, _) = with_prior(&g, &cams, &[]);
        let cost = |x: &[f64]| p.linearize(x, false).cost();
        let on = p.start((Point3::origin(), 26.0));
        assert!(cost(&on) < 1e-12, "{}", cost(&on));
        let off = p.start((Point3::new(0.0, 0.0, 1.0), 26.0));
        assert!(cost(&off) > 1e-3, "{}", cost(&off));
    }

    #[test]
    fn finite_difference_check_rejects_a_wrong_jacobian() {
        let (g, cams, obs) = setup();
        let p = EdProblem::new(&g, &cams, &obs, EdWeights::default());
        let x = g.identity();
        let mut j = p.linearize(&x, true).dense_jacobian();
        let row = j.nrows() - 1;
        let k = (0..j.ncols())
            .max_by(|&a, &b| j[(row, a)].abs().total_cmp(&j[(row, b)].abs()))
            .unwrap();
        j[(row, k)] *= 1.01; // a 1 % error in one entry
        let mut xp = x.clone();
        xp[k] += 1e-6;
        let mut xm = x.clone();
        xm[k] -= 1e-6;
        let fd = (p.linearize(&xp, false).r[row] - p.linearize(&xm, false).r[row]) / 2e-6;
        assert!((fd - j[(row, k)]).abs() / (1.0 + fd.abs()) > 1e-5);
    }

    #[test]
    fn gauss_newton_lowers_the_cost_on_every_accepted_step() {
        let (g, cams, obs) = setup();
        let p = EdProblem::new(&g, &cams, &obs, EdWeights::default());
        let (_, info) = levenberg_marquardt(&p, g.identity(), &LmParams::default()).unwrap();
        assert!(info.costs.len() > 2);
        assert!(
            info.costs.windows(2).all(|w| w[1] < w[0]),
            "{:?}",
            info.costs
        );
        assert!(info.final_cost() < 0.05 * info.costs[0], "{:?}", info.costs);
    }
}
