//! CPU twin of `shaders/surface.wgsl`: one square panel of a surface seen along a direction,
//! orthographic, z-buffered, each triangle's corner colours interpolated and shaded by how
//! squarely it faces the viewer (0.45 + 0.55 |n . w|). The picture `reconstruction.png` is made
//! of two such panels.

use super::silhouette::for_each_covered;
use nalgebra::{Point3, Vector3};

/// Keep in sync with `View` in shaders/surface.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SurfaceView {
    /// Panel right, pixels per mm (xyz); the centre's x in the panel, pixels (w).
    pub u: [f32; 4],
    /// Panel up, pixels per mm (xyz); the centre's y in the panel, pixels (w).
    pub v: [f32; 4],
    /// The viewing direction, unit, away from the viewer (xyz); 1 / depth range, per mm (w).
    pub w: [f32; 4],
    /// The centre, mm (xyz); the panel's size, pixels (w).
    pub c: [f32; 4],
}

impl SurfaceView {
    /// A `size` x `size` panel looking along `look` at `center`, `px_per_mm` pixels per mm,
    /// depths spanning +-`extent_mm` about the centre; up is `up_hint` made square to `look`
    /// (y when the two nearly agree).
    pub fn looking(
        center: &Point3<f64>,
        look: &Vector3<f64>,
        up_hint: &Vector3<f64>,
        px_per_mm: f64,
        extent_mm: f64,
        size: u32,
    ) -> SurfaceView {
        let w = look.try_normalize(1e-12).unwrap_or(Vector3::z());
        let hint = if w.dot(up_hint).abs() > 0.95 {
            Vector3::y()
        } else {
            *up_hint
        };
        let u = hint.cross(&w).normalize();
        let v = w.cross(&u);
        let half = 0.5 * size as f64;
        let f = |a: Vector3<f64>, s: f64, last: f64| {
            [
                (a.x * s) as f32,
                (a.y * s) as f32,
                (a.z * s) as f32,
                last as f32,
            ]
        };
        SurfaceView {
            u: f(u, px_per_mm, half),
            v: f(v, px_per_mm, half),
            w: f(w, 1.0, 1.0 / extent_mm.max(1e-9)),
            c: [
                center.x as f32,
                center.y as f32,
                center.z as f32,
                size as f32,
            ],
        }
    }

    /// The panel's size, pixels.
    pub fn size(&self) -> usize {
        self.c[3].max(0.0) as usize
    }

    /// A vertex's (x, y) in the panel, pixels, and its depth in [0, 1] (near small).
    fn place(&self, p: &[f32; 4]) -> ([f32; 2], f32) {
        let d = [p[0] - self.c[0], p[1] - self.c[1], p[2] - self.c[2]];
        let dot = |a: &[f32; 4]| a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
        let depth = (0.5 + 0.5 * dot(&self.w) * self.w[3]).clamp(0.0, 1.0);
        ([self.u[3] + dot(&self.u), self.v[3] - dot(&self.v)], depth)
    }
}

/// The panel: `size` x `size` RGBA pixels, row-major from the top-left, white where no
/// triangle is. `points`: vertices (x, y, z, unused), mm; `colors`: per vertex (r, g, b,
/// unused), 0..1; `triangles`: corner ids, 3 per triangle (ids out of range draw nothing).
pub fn render_surface(
    points: &[[f32; 4]],
    colors: &[[f32; 4]],
    triangles: &[u32],
    view: &SurfaceView,
) -> Vec<[u8; 4]> {
    let n = view.size();
    let mut rgba = vec![[255u8; 4]; n * n];
    let mut zbuf = vec![1.0f32; n * n];
    let placed: Vec<([f32; 2], f32)> = points.iter().map(|p| view.place(p)).collect();
    for t in triangles.chunks_exact(3) {
        let ids = [t[0] as usize, t[1] as usize, t[2] as usize];
        if ids.iter().any(|&i| i >= points.len() || i >= colors.len()) {
            continue;
        }
        let [a, b, c] = ids.map(|i| Vector3::new(points[i][0], points[i][1], points[i][2]));
        let normal = (b - a).cross(&(c - a));
        let len = normal.norm();
        let facing = if len > 0.0 {
            (normal / len)
                .dot(&Vector3::new(view.w[0], view.w[1], view.w[2]))
                .abs()
        } else {
            1.0
        };
        let shade = 0.45 + 0.55 * facing;
        let corners = ids.map(|i| placed[i].0);
        for_each_covered(corners, n, n, |x, y, bary| {
            let at = y * n + x;
            let depth: f32 = (0..3).map(|k| bary[k] * placed[ids[k]].1).sum();
            if depth < zbuf[at] {
                zbuf[at] = depth;
                let mut px = [255u8; 4];
                for (ch, out) in px.iter_mut().take(3).enumerate() {
                    let v: f32 = (0..3).map(|k| bary[k] * colors[ids[k]][ch]).sum();
                    *out = ((v * shade).clamp(0.0, 1.0) * 255.0).round() as u8;
                }
                rgba[at] = px;
            }
        });
    }
    rgba
}
