//! The order spade's bulk load inserts points in, found cheaply: the alpha shapes triangulate
//! a few thousand projected vertices dozens of times a reconstruction, and spade's own sort of
//! them took a fifth of its bulk load (190 M of 890 M instructions in a level-3 run).

use spade::HasPosition;

/// A projected model vertex, as the triangulation holds it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Site {
    /// Position, pixels.
    pub(super) p: spade::Point2<f64>,
    /// The model vertex it came from.
    pub(super) id: u32,
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> spade::Point2<f64> {
        self.p
    }
}

/// spade's bulk load (2.15) first sorts its input by (distance to the input's centroid,
/// descending; x; y), recomputing that key at every comparison of a general-purpose sort, and
/// inserts the points nearest first; the triangulation's vertex and face numbers, and so where
/// the traced outline starts, follow that order. Here the same order is found with each key
/// computed once, so spade's sort meets a sorted input and only checks it. The input is given
/// back as it came whenever that order might not be spade's own: two sites with the same key
/// (the same position), or an order that the centroid of the sorted list (summed in another
/// order, so perhaps a rounding apart) would not keep. Either way the triangulation is the one
/// spade builds from `sites` (test: `presorting_keeps_spades_triangulation`).
pub(super) fn in_bulk_load_order(sites: Vec<Site>) -> Vec<Site> {
    if sites.len() < 3 {
        return sites;
    }
    // spade's centroid: the positions summed in list order, times 1 / len.
    let centroid = |s: &[Site]| {
        let (mut x, mut y) = (0.0, 0.0);
        for v in s {
            x += v.p.x;
            y += v.p.y;
        }
        let f = 1.0 / s.len() as f64;
        (x * f, y * f)
    };
    let dist2 = |c: (f64, f64), p: spade::Point2<f64>| {
        let (dx, dy) = (c.0 - p.x, c.1 - p.y);
        dx * dx + dy * dy
    };
    // spade's order: farther first, then x, then y (its pop takes the nearest first).
    let before = |da: f64, a: &Site, db: f64, b: &Site| {
        db.partial_cmp(&da)
            .and_then(|o| Some(o.then(a.p.x.partial_cmp(&b.p.x)?)))
            .and_then(|o| Some(o.then(a.p.y.partial_cmp(&b.p.y)?)))
    };
    let strictly_sorted = |s: &[Site], c: (f64, f64)| {
        s.windows(2).all(|w| {
            before(dist2(c, w[0].p), &w[0], dist2(c, w[1].p), &w[1])
                == Some(std::cmp::Ordering::Less)
        })
    };
    let c0 = centroid(&sites);
    // Sort keys as integers in f64::total_cmp's order (the distance descending); the checks
    // below use spade's comparison, under which -0 and +0 are one value.
    let ordered = |v: f64| {
        let b = v.to_bits();
        if b >> 63 == 1 {
            !b
        } else {
            b | 1 << 63
        }
    };
    let mut keys: Vec<(u64, u64, u64, u32)> = Vec::with_capacity(sites.len());
    for (i, s) in sites.iter().enumerate() {
        let d = dist2(c0, s.p);
        if !d.is_finite() {
            return sites;
        }
        keys.push((!ordered(d), ordered(s.p.x), ordered(s.p.y), i as u32));
    }
    keys.sort_unstable();
    let sorted: Vec<Site> = keys.iter().map(|k| sites[k.3 as usize]).collect();
    // Strict under the sorted list's centroid: then spade keeps this order. It is also the
    // order spade gives the input as it came (`c0`'s): `keys` sorted it so, and two sites tied
    // under c0 (equal distance, x and y, so one position) would be tied here too.
    if strictly_sorted(&sorted, centroid(&sorted)) {
        sorted
    } else {
        sites
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spade::{DelaunayTriangulation, Triangulation};

    /// Vertices (position, id) in handle order and faces (vertex handles) of a triangulation.
    type Fingerprint = (Vec<(f64, f64, u32)>, Vec<[usize; 3]>);

    fn fingerprint(tri: &DelaunayTriangulation<Site>) -> Fingerprint {
        let v = tri
            .vertices()
            .map(|v| (v.position().x, v.position().y, v.data().id))
            .collect();
        let f = tri
            .inner_faces()
            .map(|f| f.vertices().map(|v| v.fix().index()))
            .collect();
        (v, f)
    }

    fn sites_of(points: &[(f64, f64)]) -> Vec<Site> {
        points
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| Site {
                p: spade::Point2::new(x, y),
                id: i as u32,
            })
            .collect()
    }

    fn both_ways(sites: Vec<Site>) -> (Fingerprint, Fingerprint) {
        let plain = DelaunayTriangulation::<Site>::bulk_load(sites.clone()).unwrap();
        let pre = DelaunayTriangulation::<Site>::bulk_load(in_bulk_load_order(sites)).unwrap();
        (fingerprint(&plain), fingerprint(&pre))
    }

    /// Point sets like the model's: random clouds, a hemisphere's rings seen along and across
    /// its axis (many equal distances to the centroid, told apart by x and y), a grid, and
    /// points a rounding apart.
    fn point_sets() -> Vec<Vec<(f64, f64)>> {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut sets = Vec::new();
        for n in [3, 4, 10, 100, 2000] {
            sets.push(
                (0..n)
                    .map(|_| (rng.random_range(0.0..800.0), rng.random_range(-50.0..300.0)))
                    .collect(),
            );
        }
        for tilt in [0.0f64, 0.3, 1.2] {
            let mut pts = Vec::new();
            for ring in 0..=20 {
                let polar = ring as f64 / 20.0 * std::f64::consts::FRAC_PI_2;
                let count = (ring * 6).max(1);
                for k in 0..count {
                    let az = k as f64 / count as f64 * std::f64::consts::TAU;
                    let (x, y, z) = (polar.sin() * az.cos(), polar.sin() * az.sin(), polar.cos());
                    let (y, _z) = (
                        y * tilt.cos() - z * tilt.sin(),
                        y * tilt.sin() + z * tilt.cos(),
                    );
                    pts.push((512.0 + 100.0 * x, 400.0 + 100.0 * y));
                }
            }
            sets.push(pts);
        }
        sets.push(
            (0..30)
                .flat_map(|i| (0..30).map(move |j| (i as f64, j as f64)))
                .collect(),
        );
        sets.push(
            (0..200)
                .map(|i| (1.0 + i as f64 * f64::EPSILON, 1.0 + (i % 7) as f64))
                .collect(),
        );
        sets
    }

    #[test]
    fn presorting_keeps_spades_triangulation() {
        let mut presorted = 0;
        for (k, pts) in point_sets().into_iter().enumerate() {
            let sites = sites_of(&pts);
            let moved = in_bulk_load_order(sites.clone());
            if moved.iter().zip(&sites).any(|(a, b)| a.id != b.id) {
                presorted += 1;
            }
            let (plain, pre) = both_ways(sites);
            assert_eq!(plain, pre, "point set {k}");
        }
        // Every set but the three smallest (which may come sorted) went the presorted way.
        assert!(presorted >= 7, "{presorted} of 10 sets presorted");
    }

    #[test]
    fn an_order_that_matters_is_left_to_spade() {
        // Two sites at one position: which of them the triangulation keeps depends on the
        // order, and the fingerprint tells the two orders apart...
        let mut pts: Vec<(f64, f64)> = point_sets().swap_remove(3);
        pts.push(pts[17]);
        let sites = sites_of(&pts);
        let mut swapped = sites.clone();
        let last = swapped.len() - 1;
        swapped.swap(17, last);
        let a = fingerprint(&DelaunayTriangulation::<Site>::bulk_load(sites.clone()).unwrap());
        let b = fingerprint(&DelaunayTriangulation::<Site>::bulk_load(swapped).unwrap());
        assert_ne!(a, b, "the comparison sees a different order");
        // ... so the presort gives such an input back untouched.
        let kept = in_bulk_load_order(sites.clone());
        assert!(kept.iter().zip(&sites).all(|(x, y)| x.id == y.id));
        let (plain, pre) = both_ways(sites);
        assert_eq!(plain, pre);
    }
}
