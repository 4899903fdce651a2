//! CPU twin of `shaders/deform.wgsl`: embedded-deformation vertex update for a batch of meshes,
//! v_i = sum_k w_ik (A_j (P_i - g_j) + g_j + t_j) over the m nearest nodes j of vertex i, returned
//! as the displacement v_i - P_i = sum_k w_ik ((A_j - I)(P_i - g_j) + t_j) (weights sum to one),
//! so f32 carries only the motion; `DeformBatch::positions` adds it to the f64 rest positions.

use crate::solve::DeformationGraph;
use nalgebra::Point3;

/// The inputs of one batch, flattened as the kernel reads them (all meshes share V, J and m).
#[derive(Clone, Debug, PartialEq)]
pub struct DeformBatch {
    /// Vertices per mesh.
    pub vertex_count: u32,
    /// Graph nodes per mesh.
    pub node_count: u32,
    /// Nodes each vertex follows.
    pub neighbours: u32,
    /// Meshes in the batch.
    pub mesh_count: u32,
    /// B * V rest positions (w unused).
    pub rest: Vec<[f32; 4]>,
    /// B * J node positions.
    pub nodes: Vec<[f32; 4]>,
    /// B * J * 3 rows (row r of A - I, t_r).
    pub affine: Vec<[f32; 4]>,
    /// B * V * m node indices (within the mesh) and weights.
    pub node_index: Vec<u32>,
    /// Per vertex and neighbour, its weight.
    pub weight: Vec<f32>,
}

/// Why a batch cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DeformBatchError {
    /// No mesh in the batch.
    #[error("the batch is empty")]
    Empty,
    /// A mesh whose graph differs in shape from the batch's first.
    #[error("mesh {mesh}: {what} is {got}, the batch's first mesh has {expected}")]
    Shape {
        /// The mesh's index in the batch.
        mesh: usize,
        /// What differs (vertices, nodes, neighbours).
        what: &'static str,
        /// Its count.
        got: usize,
        /// The first mesh's.
        expected: usize,
    },
    /// A parameter vector of the wrong length.
    #[error("mesh {mesh}: parameter vector has {got} values, {expected} expected")]
    Params {
        /// The mesh's index in the batch.
        mesh: usize,
        /// Its length.
        got: usize,
        /// The graph's parameter count.
        expected: usize,
    },
}

impl DeformBatch {
    /// Flatten graphs and their parameter vectors (12 per node: A row-major, then t). Every
    /// vertex gets exactly m (node, weight) pairs; a vertex with fewer is padded with weight 0.
    pub fn from_graphs(items: &[(&DeformationGraph, &[f64])]) -> Result<Self, DeformBatchError> {
        let (g0, _) = items.first().ok_or(DeformBatchError::Empty)?;
        let v = g0.rest.len();
        let j = g0.node_count();
        let m = g0.weights.iter().map(|w| w.len()).max().unwrap_or(0);
        let mut b = DeformBatch {
            vertex_count: v as u32,
            node_count: j as u32,
            neighbours: m as u32,
            mesh_count: items.len() as u32,
            rest: Vec::with_capacity(items.len() * v),
            nodes: Vec::with_capacity(items.len() * j),
            affine: Vec::with_capacity(items.len() * j * 3),
            node_index: Vec::with_capacity(items.len() * v * m),
            weight: Vec::with_capacity(items.len() * v * m),
        };
        for (mesh, (g, x)) in items.iter().enumerate() {
            for (what, got, expected) in [
                ("vertex count", g.rest.len(), v),
                ("node count", g.node_count(), j),
            ] {
                if got != expected {
                    return Err(DeformBatchError::Shape {
                        mesh,
                        what,
                        got,
                        expected,
                    });
                }
            }
            if x.len() != 12 * j {
                return Err(DeformBatchError::Params {
                    mesh,
                    got: x.len(),
                    expected: 12 * j,
                });
            }
            b.rest.extend(g.rest.iter().map(to4));
            b.nodes.extend(g.nodes.iter().map(to4));
            for n in 0..j {
                let (a, t) = DeformationGraph::affine(x, n);
                let a = a - nalgebra::Matrix3::identity();
                for r in 0..3 {
                    b.affine.push([
                        a[(r, 0)] as f32,
                        a[(r, 1)] as f32,
                        a[(r, 2)] as f32,
                        t[r] as f32,
                    ]);
                }
            }
            for w in &g.weights {
                for k in 0..m {
                    let (n, wt) = w.get(k).copied().unwrap_or((0, 0.0));
                    b.node_index.push(n);
                    b.weight.push(wt as f32);
                }
            }
        }
        Ok(b)
    }
}

fn to4(p: &Point3<f64>) -> [f32; 4] {
    [p.x as f32, p.y as f32, p.z as f32, 0.0]
}

fn dot3(a: &[f32; 4], d: [f32; 3]) -> f32 {
    a[0] * d[0] + a[1] * d[1] + a[2] * d[2]
}

/// Deformed positions of mesh `mesh` of the batch: f64 rest positions plus the kernel's
/// displacements.
pub fn positions(rest: &[Point3<f64>], displacement: &[[f32; 4]]) -> Vec<Point3<f64>> {
    rest.iter()
        .zip(displacement)
        .map(|(p, d)| Point3::new(p.x + d[0] as f64, p.y + d[1] as f64, p.z + d[2] as f64))
        .collect()
}

/// The kernel's loop on the CPU: one displacement per (mesh, vertex), xyz and w = 1.
pub fn deform(b: &DeformBatch) -> Vec<[f32; 4]> {
    let (nv, m) = (b.vertex_count as usize, b.neighbours as usize);
    let mut out = vec![[0.0f32; 4]; b.rest.len()];
    for mesh in 0..b.mesh_count as usize {
        for i in 0..nv {
            let v = mesh * nv + i;
            let p = b.rest[v];
            let mut acc = [0.0f32; 3];
            for k in 0..m {
                let e = v * m + k;
                let j = mesh * b.node_count as usize + b.node_index[e] as usize;
                let g = b.nodes[j];
                let d = [p[0] - g[0], p[1] - g[1], p[2] - g[2]];
                let (r0, r1, r2) = (&b.affine[3 * j], &b.affine[3 * j + 1], &b.affine[3 * j + 2]);
                let moved = [
                    dot3(r0, d) + r0[3],
                    dot3(r1, d) + r1[3],
                    dot3(r2, d) + r2[3],
                ];
                let w = b.weight[e];
                for c in 0..3 {
                    acc[c] += w * moved[c];
                }
            }
            out[v] = [acc[0], acc[1], acc[2], 1.0];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::GraphParams;
    use crate::template::hemisphere;

    #[test]
    fn twin_matches_the_f64_deformation() {
        let mesh = hemisphere(26.0, 600);
        let g = DeformationGraph::new(&mesh, &GraphParams::default());
        let mut x = g.identity();
        for (k, v) in x.iter_mut().enumerate() {
            *v += 0.01 * ((k * 7919 % 13) as f64 - 6.0);
        }
        let b = DeformBatch::from_graphs(&[(&g, &x)]).unwrap();
        let f32s = deform(&b);
        let f64s = g.deform(&x);
        let worst = positions(&g.rest, &f32s)
            .iter()
            .zip(&f64s)
            .map(|(a, p)| (a - p).norm())
            .fold(0.0, f64::max);
        // f32 carries only the motion (~1 mm): errors of order 1e-7 mm, far below 1e-5.
        assert!(worst < 1e-5, "f32 twin off by {worst} mm");
        // Companion: a wrong parameter vector moves the result well beyond that bound.
        x[9] += 1.0;
        let wrong = deform(&DeformBatch::from_graphs(&[(&g, &x)]).unwrap());
        let moved = wrong
            .iter()
            .zip(&f32s)
            .map(|(a, b)| (a[0] - b[0]).abs())
            .fold(0.0f32, f32::max);
        assert!(moved > 0.1);
    }

    #[test]
    fn mismatched_batches_are_errors() {
        let g1 = DeformationGraph::new(&hemisphere(26.0, 600), &GraphParams::default());
        let g2 = DeformationGraph::new(&hemisphere(26.0, 700), &GraphParams::default());
        let (x1, x2) = (g1.identity(), g2.identity());
        assert!(matches!(
            DeformBatch::from_graphs(&[(&g1, &x1), (&g2, &x2)]),
            Err(DeformBatchError::Shape { mesh: 1, .. })
        ));
        assert!(matches!(
            DeformBatch::from_graphs(&[(&g1, &x1[..12])]),
            Err(DeformBatchError::Params { mesh: 0, .. })
        ));
        assert_eq!(DeformBatch::from_graphs(&[]), Err(DeformBatchError::Empty));
    }
}
