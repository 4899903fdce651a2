//! CPU twin of `shaders/project.wgsl`: perspective projection of a batch of meshes into a batch
//! of views, (u, v, depth, valid) per vertex.

use crate::views::Camera;

/// Smallest depth in front of the source, as in the kernel (and `views::camera::MIN_DEPTH`).
pub const MIN_DEPTH: f32 = 1e-3;

/// One view as the kernel reads it: rows of [R | t], then (fx, fy, cx, cy).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewRows {
    /// Rows of [R | t] (keep in sync with shaders/project.wgsl).
    pub r: [[f32; 4]; 3],
    /// fx, fy, cx, cy.
    pub k: [f32; 4],
}

impl ViewRows {
    /// The rows of camera `c`, in f32.
    pub fn from_camera(c: &Camera) -> Self {
        let m = c.r.matrix();
        let row = |i: usize| {
            [
                m[(i, 0)] as f32,
                m[(i, 1)] as f32,
                m[(i, 2)] as f32,
                c.t[i] as f32,
            ]
        };
        ViewRows {
            r: [row(0), row(1), row(2)],
            k: [c.k.fx as f32, c.k.fy as f32, c.k.cx as f32, c.k.cy as f32],
        }
    }
}

fn dot3(a: &[f32; 4], p: &[f32; 4]) -> f32 {
    a[0] * p[0] + a[1] * p[1] + a[2] * p[2]
}

/// `vertices`: B * V positions; output index (mesh * C + view) * V + vertex.
pub fn project(vertices: &[[f32; 4]], vertex_count: usize, views: &[ViewRows]) -> Vec<[f32; 4]> {
    let meshes = vertices.len().checked_div(vertex_count).unwrap_or(0);
    let mut out = vec![[0.0f32; 4]; meshes * views.len() * vertex_count];
    for b in 0..meshes {
        for (c, view) in views.iter().enumerate() {
            let bc = b * views.len() + c;
            for i in 0..vertex_count {
                let p = &vertices[b * vertex_count + i];
                let x = dot3(&view.r[0], p) + view.r[0][3];
                let y = dot3(&view.r[1], p) + view.r[1][3];
                let z = dot3(&view.r[2], p) + view.r[2][3];
                out[bc * vertex_count + i] = if z > MIN_DEPTH {
                    [
                        view.k[0] * x / z + view.k[2],
                        view.k[1] * y / z + view.k[3],
                        z,
                        1.0,
                    ]
                } else {
                    [0.0, 0.0, z, 0.0]
                };
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{simulated_views, XrayGeometry};
    use nalgebra::Point3;

    #[test]
    fn twin_matches_the_f64_camera() {
        let cams = simulated_views(&XrayGeometry::default(), &Point3::new(10.0, -5.0, 3.0));
        let pts: Vec<Point3<f64>> = (0..50)
            .map(|i| {
                Point3::new(
                    10.0 + i as f64 * 0.5,
                    -5.0 + (i % 7) as f64,
                    3.0 - i as f64 * 0.2,
                )
            })
            .collect();
        let v: Vec<[f32; 4]> = pts
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
            .collect();
        let rows: Vec<ViewRows> = cams.iter().map(ViewRows::from_camera).collect();
        let out = project(&v, v.len(), &rows);
        for (c, cam) in cams.iter().enumerate() {
            for (i, p) in pts.iter().enumerate() {
                let e = cam.project(p).unwrap();
                let g = out[c * pts.len() + i];
                assert_eq!(g[3], 1.0);
                // f32 at ~1,000 mm from the source and ~10,000 px: a few 1e-3 px.
                assert!((g[0] as f64 - e.x).abs() < 0.02 && (g[1] as f64 - e.y).abs() < 0.02);
            }
        }
    }
}
