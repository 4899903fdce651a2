//! CPU twin of `shaders/silhouette.wgsl`: rasterise a projected mesh into an id image (texel =
//! 1 + nearest corner's vertex id, 0 = background), mark the silhouette texels, and trace them
//! into an ordered closed loop of vertex ids.

/// The image window the id texture covers (keep in sync with `Window` in the shader).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    /// Image position of the texture's top-left corner, pixels.
    pub x0: f32,
    /// Image y of the texture's top-left corner, pixels.
    pub y0: f32,
    /// Image pixels per texel.
    pub scale: f32,
    /// Texels per side.
    pub size: u32,
}

impl Window {
    /// A square window around the valid projected points with a 4 % margin.
    pub fn around(projected: &[[f32; 4]], size: u32) -> Option<Window> {
        let valid = projected
            .iter()
            .filter(|p| p[3] > 0.5 && p[0].is_finite() && p[1].is_finite());
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        let mut any = false;
        for p in valid {
            any = true;
            for c in 0..2 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        if !any || size < 4 {
            return None;
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-3) * 1.08;
        let cx = 0.5 * (lo[0] + hi[0]);
        let cy = 0.5 * (lo[1] + hi[1]);
        Some(Window {
            x0: cx - 0.5 * extent,
            y0: cy - 0.5 * extent,
            scale: extent / size as f32,
            size,
        })
    }

    /// Image position of texel (x, y)'s centre.
    pub fn texel_centre(&self, x: u32, y: u32) -> [f32; 2] {
        [
            self.x0 + (x as f32 + 0.5) * self.scale,
            self.y0 + (y as f32 + 0.5) * self.scale,
        ]
    }
}

fn edge(a: [f32; 2], b: [f32; 2], p: [f32; 2]) -> f32 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// Every cell (x, y) of a `w` x `h` grid whose centre (x + 0.5, y + 0.5) lies inside triangle
/// `c` (either winding; edges included), with its barycentric weights. Degenerate or non-finite
/// triangles cover nothing.
pub fn for_each_covered(
    c: [[f32; 2]; 3],
    w: usize,
    h: usize,
    mut f: impl FnMut(usize, usize, [f32; 3]),
) {
    let area = edge(c[0], c[1], c[2]);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let lo = |k: usize| {
        c.iter()
            .map(|p| p[k])
            .fold(f32::INFINITY, f32::min)
            .floor()
            .max(0.0) as usize
    };
    let hi = |k: usize, n: usize| {
        (c.iter()
            .map(|p| p[k])
            .fold(f32::NEG_INFINITY, f32::max)
            .ceil() as usize)
            .min(n)
    };
    for y in lo(1)..hi(1, h) {
        for x in lo(0)..hi(0, w) {
            let p = [x as f32 + 0.5, y as f32 + 0.5];
            let b = [
                edge(c[1], c[2], p) / area,
                edge(c[2], c[0], p) / area,
                edge(c[0], c[1], p) / area,
            ];
            if b.iter().all(|&v| v >= 0.0) {
                f(x, y, b);
            }
        }
    }
}

/// The render pass on the CPU: every triangle in order, texel centres inside it (either winding)
/// take 1 + the id of the corner with the largest barycentric weight (first corner on ties);
/// later triangles overwrite earlier ones, as the GPU's primitive order does. Texel coverage
/// on shared edges may differ from the GPU's fixed-point rules by a texel; the comparison test
/// states that bound.
pub fn rasterise(projected: &[[f32; 4]], triangles: &[u32], w: &Window) -> Vec<u32> {
    let n = w.size as usize;
    let mut ids = vec![0u32; n * n];
    let to_tex = |p: &[f32; 4]| [(p[0] - w.x0) / w.scale, (p[1] - w.y0) / w.scale];
    for t in triangles.chunks_exact(3) {
        let Some(c) = t
            .iter()
            .map(|&i| projected.get(i as usize).filter(|p| p[3] > 0.5).map(to_tex))
            .collect::<Option<Vec<[f32; 2]>>>()
        else {
            continue;
        };
        let c = [c[0], c[1], c[2]];
        for_each_covered(c, n, n, |x, y, b| {
            let mut k = 0;
            if b[1] > b[k] {
                k = 1;
            }
            if b[2] > b[k] {
                k = 2;
            }
            ids[y * n + x] = t[k] + 1;
        });
    }
    ids
}

/// The edge kernel on the CPU: texel value on the silhouette (covered, with an uncovered
/// 4-neighbour or the border beside it), 0 elsewhere.
pub fn edges(ids: &[u32], size: u32) -> Vec<u32> {
    let n = size as i64;
    let covered =
        |x: i64, y: i64| x >= 0 && y >= 0 && x < n && y < n && ids[(y * n + x) as usize] != 0;
    let mut mask = vec![0u32; ids.len()];
    for y in 0..n {
        for x in 0..n {
            let id = ids[(y * n + x) as usize];
            if id != 0
                && !(covered(x - 1, y)
                    && covered(x + 1, y)
                    && covered(x, y - 1)
                    && covered(x, y + 1))
            {
                mask[(y * n + x) as usize] = id;
            }
        }
    }
    mask
}

/// Trace the outer boundary of the largest silhouette component (Moore-neighbour tracing,
/// clockwise in image axes) and return its vertex ids in order, consecutive repeats merged and
/// each id kept once (first visit). Empty when the mask is empty.
pub fn trace(mask: &[u32], size: u32) -> Vec<u32> {
    let n = size as i64;
    let on = |x: i64, y: i64| x >= 0 && y >= 0 && x < n && y < n && mask[(y * n + x) as usize] != 0;
    // Start: the top-most, then left-most silhouette texel of the largest 8-connected component.
    let mut label = vec![0u32; mask.len()];
    let mut best: Option<(usize, (i64, i64))> = None;
    let mut next = 1u32;
    for y in 0..n {
        for x in 0..n {
            if !on(x, y) || label[(y * n + x) as usize] != 0 {
                continue;
            }
            let mut stack = vec![(x, y)];
            label[(y * n + x) as usize] = next;
            let mut count = 0usize;
            while let Some((px, py)) = stack.pop() {
                count += 1;
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (qx, qy) = (px + dx, py + dy);
                        if on(qx, qy) && label[(qy * n + qx) as usize] == 0 {
                            label[(qy * n + qx) as usize] = next;
                            stack.push((qx, qy));
                        }
                    }
                }
            }
            if best.is_none_or(|b| count > b.0) {
                best = Some((count, (x, y)));
            }
            next += 1;
        }
    }
    let Some((_, start)) = best else {
        return Vec::new();
    };
    let comp = label[(start.1 * n + start.0) as usize];
    let inside = |x: i64, y: i64| on(x, y) && label[(y * n + x) as usize] == comp;
    // Moore neighbourhood, clockwise from west (image y down).
    const DIRS: [(i64, i64); 8] = [
        (-1, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
        (1, 0),
        (1, 1),
        (0, 1),
        (-1, 1),
    ];
    let mut out: Vec<u32> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut push = |x: i64, y: i64| {
        let id = mask[(y * n + x) as usize] - 1;
        if seen.insert(id) {
            out.push(id);
        }
    };
    let mut cur = start;
    // We entered the start from the west (it is the first texel of its row scan).
    let mut from = 0usize;
    push(cur.0, cur.1);
    let limit = 4 * mask.len() + 8;
    for _ in 0..limit {
        let mut moved = false;
        for k in 0..8 {
            let d = (from + 1 + k) % 8;
            let (qx, qy) = (cur.0 + DIRS[d].0, cur.1 + DIRS[d].1);
            if inside(qx, qy) {
                // Next search starts from the neighbour before d, seen from the new texel.
                from = (d + 4) % 8;
                cur = (qx, qy);
                moved = true;
                break;
            }
        }
        if !moved || cur == start {
            break;
        }
        push(cur.0, cur.1);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fan of triangles around a centre: a regular polygon of `k` rim vertices.
    fn disc(k: usize, r: f32) -> (Vec<[f32; 4]>, Vec<u32>) {
        let mut p = vec![[50.0, 50.0, 1000.0, 1.0]];
        for i in 0..k {
            let a = std::f32::consts::TAU * i as f32 / k as f32;
            p.push([50.0 + r * a.cos(), 50.0 + r * a.sin(), 1000.0, 1.0]);
        }
        let t = (0..k as u32)
            .flat_map(|i| [0, 1 + i, 1 + (i + 1) % k as u32])
            .collect();
        (p, t)
    }

    #[test]
    fn a_disc_traces_to_its_rim_vertices_in_order() {
        let (p, t) = disc(24, 30.0);
        let w = Window::around(&p, 128).unwrap();
        let ids = rasterise(&p, &t, &w);
        let mask = edges(&ids, w.size);
        let loop_ids = trace(&mask, w.size);
        // Every rim vertex appears, the centre never, and consecutive rim ids step by one.
        assert_eq!(loop_ids.len(), 24, "{loop_ids:?}");
        assert!(!loop_ids.contains(&0));
        let steps_ok = loop_ids
            .windows(2)
            .filter(|w| {
                (w[1] as i64 - w[0] as i64).rem_euclid(24) == 1
                    || (w[0] as i64 - w[1] as i64).rem_euclid(24) == 1
            })
            .count();
        assert!(steps_ok >= 22, "{loop_ids:?}");
    }

    #[test]
    fn edges_mark_only_the_rim_of_a_filled_square() {
        let n = 8u32;
        let mut ids = vec![0u32; 64];
        for y in 2..6 {
            for x in 2..6 {
                ids[y * 8 + x] = 7;
            }
        }
        let mask = edges(&ids, n);
        assert_eq!(mask.iter().filter(|&&m| m == 7).count(), 12);
        assert_eq!(mask[3 * 8 + 3], 0);
        // Companion: a mask with an interior texel set differs from the twin's answer.
        let mut wrong = mask.clone();
        wrong[3 * 8 + 3] = 7;
        assert_ne!(wrong, edges(&ids, n));
    }
}
