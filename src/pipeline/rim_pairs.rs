//! Pairs the rim makes: where an observed outline point's ray passes well inside the surface's
//! sphere, the acetabulum's rim forms the outline there, not its limb (a limb ray grazes the
//! sphere). The template is a hemisphere, wider than most acetabula (the shared ones end 65-80
//! degrees from the dome), so a model vertex away from the model's own border that is paired
//! with such a point is part of the cap's surplus beyond the true rim: pulled onto the outline,
//! the surplus crushes inwards, and the cup fitted to the observed part shrinks with it.
//! `weigh` lowers those pairs' weight, leaving the model's border (and the ring next to it) to
//! meet the rim-formed outline and the surplus to the sphere prior. Measured in
//! docs/population.md, "Pairs the rim makes".

use crate::correspond::Observation;
use crate::geom::{fit_sphere_robust, Mesh};
use crate::views::Camera;

/// About this many of the surface's vertices (every k-th) give its sphere.
const SPHERE_VERTICES: usize = 400;

/// Which pairs are the rim's, and what they weigh.
#[derive(Clone, Debug, PartialEq)]
pub struct RimPairs {
    /// A pair is the rim's when its observed point's ray passes the surface's sphere centre
    /// closer than this share of the sphere's radius (default `solve::RIM_WITHIN`, 0.93: the
    /// share the rim fit takes for the rim).
    pub within: f64,
    /// Such a pair's weight is multiplied by this (default 0.3; at most 0.5, so that the
    /// observed-part cup leaves its vertex out).
    pub weight: f64,
    /// Model vertices this many rings or fewer from the model's border keep their weight: the
    /// model's own rim is what meets a rim-formed outline (default 1: the border and the ring
    /// next to it).
    pub border_rings: usize,
}

impl Default for RimPairs {
    fn default() -> Self {
        RimPairs {
            within: crate::solve::RIM_WITHIN,
            weight: 0.3,
            border_rings: 1,
        }
    }
}

/// Each vertex's distance in edges from the border of `mesh`, counted up to `most`
/// (farther vertices get `most + 1`; a mesh without border: all `most + 1`).
pub(super) fn border_rings(mesh: &Mesh, most: usize) -> Vec<usize> {
    let far = most.saturating_add(1);
    let mut ring = vec![far; mesh.vertex_count()];
    for e in mesh.boundary_edges() {
        for v in e {
            ring[v as usize] = 0;
        }
    }
    let edges = mesh.edges();
    // Ring r + 1 from ring r, until `most` or until a ring is empty (no vertex lies farther).
    for r in 0..most {
        let mut grew = false;
        let mut next = ring.clone();
        for &[a, b] in &edges {
            let (a, b) = (a as usize, b as usize);
            if ring[a] == r && next[b] > r + 1 {
                next[b] = r + 1;
                grew = true;
            }
            if ring[b] == r && next[a] > r + 1 {
                next[a] = r + 1;
                grew = true;
            }
        }
        ring = next;
        if !grew {
            break;
        }
    }
    ring
}

/// Multiply by `prm.weight` the weight of every pair in `obs` that the rim makes (see the
/// module doc) and whose model vertex lies more than `prm.border_rings` rings from the border of
/// `mesh`, its observed point seen in `cams[pair.view]`. The sphere is the robust sphere of the
/// surface's vertices (`SPHERE_VERTICES` of them); when none fits, nothing changes. Returns how many pairs were lowered.
pub(super) fn weigh(
    mesh: &Mesh,
    cams: &[Camera],
    obs: &mut [Observation],
    prm: &RimPairs,
) -> usize {
    // Every k-th vertex: the same sphere to a fraction of a millimetre at a fraction of the
    // fit's cost (it runs before every correspondence round).
    let k = mesh.vertex_count().div_ceil(SPHERE_VERTICES).max(1);
    let sample: Vec<_> = mesh.vertices.iter().step_by(k).copied().collect();
    let Ok(sphere) = fit_sphere_robust(&sample) else {
        return 0;
    };
    let centre = sphere.center_point();
    let inside = prm.within * sphere.radius;
    let ring = border_rings(mesh, prm.border_rings);
    let mut lowered = 0;
    for o in obs.iter_mut() {
        if ring
            .get(o.vertex as usize)
            .is_none_or(|&r| r <= prm.border_rings)
        {
            continue;
        }
        let Some(cam) = cams.get(o.view) else {
            continue;
        };
        // A unit vector; NaN for a NaN target, which then lowers nothing.
        let dir = cam.ray(&o.target);
        let to_centre = centre - cam.center();
        let miss = (to_centre - dir * to_centre.dot(&dir)).norm();
        if miss < inside {
            o.weight *= prm.weight;
            lowered += 1;
        }
    }
    lowered
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{simulated_views, XrayGeometry};
    use crate::template::hemisphere;
    use nalgebra::{Point3, Vector2};

    /// A pair of `vertex` in view 0 whose observed point is where `p` projects.
    fn pair(cams: &[Camera], vertex: u32, p: &Point3<f64>) -> Observation {
        Observation {
            view: 0,
            vertex,
            target: cams[0].project(p).unwrap(),
            weight: 1.0,
            normal: Vector2::zeros(),
        }
    }

    /// A point `share` of the radius from the centre, across view 0's line of sight: the ray
    /// through it passes the centre that far off (to 0.05 % at the study's 900 mm).
    fn across(cams: &[Camera], share: f64, r: f64) -> Point3<f64> {
        let to_c = (Point3::origin() - cams[0].center()).normalize();
        let side = to_c.cross(&nalgebra::Vector3::z()).normalize();
        Point3::origin() + side * (share * r)
    }

    #[test]
    fn rings_count_edges_from_the_border() {
        let m = hemisphere(25.0, 800);
        let ring = border_rings(&m, 2);
        let border: std::collections::HashSet<u32> =
            m.boundary_edges().into_iter().flatten().collect();
        let edges = m.edges();
        // The smallest ring among a vertex's neighbours.
        let nearest = |v: usize| {
            edges
                .iter()
                .filter_map(|&[a, b]| match (a as usize, b as usize) {
                    (a, b) if a == v => Some(ring[b]),
                    (a, b) if b == v => Some(ring[a]),
                    _ => None,
                })
                .min()
                .unwrap()
        };
        for (v, &r) in ring.iter().enumerate() {
            assert_eq!(r == 0, border.contains(&(v as u32)), "vertex {v}");
            match r {
                0 => {}
                1 | 2 => assert_eq!(nearest(v), r - 1, "vertex {v}"),
                _ => assert_eq!(r, 3, "vertex {v}"),
            }
            if r == 3 {
                assert!(nearest(v) >= 2, "vertex {v}");
            }
        }
        assert!((0..=3).all(|k| ring.contains(&k)));
        // Companion: counted up to 0, every vertex off the border is just "farther".
        let none = border_rings(&m, 0);
        assert!(none.iter().all(|&r| r <= 1));
        assert_eq!(none.iter().filter(|&&r| r == 0).count(), border.len());
    }

    #[test]
    fn only_pairs_of_rim_rays_away_from_the_border_weigh_less() {
        let r = 25.0;
        let m = hemisphere(r, 1500);
        let cams = simulated_views(&XrayGeometry::default(), &Point3::origin());
        let ring = border_rings(&m, 1);
        let at = |k: usize| ring.iter().position(|&r| r == k).unwrap() as u32;
        let (interior, next, border) = (at(2), at(1), at(0));
        let prm = RimPairs::default();
        let mut obs = vec![
            pair(&cams, interior, &across(&cams, 0.0, r)), // through the centre: the rim's
            pair(&cams, interior, &across(&cams, 0.90, r)), // inside 0.93 R: the rim's
            pair(&cams, interior, &across(&cams, 0.96, r)), // outside it: the limb's
            pair(&cams, interior, &across(&cams, 1.0, r)), // the limb itself
            pair(&cams, next, &across(&cams, 0.0, r)),     // next to the model's own rim
            pair(&cams, border, &across(&cams, 0.0, r)),   // the model's own rim
        ];
        let lowered = weigh(&m, &cams, &mut obs, &prm);
        let w: Vec<f64> = obs.iter().map(|o| o.weight).collect();
        assert_eq!(w, [0.3, 0.3, 1.0, 1.0, 1.0, 1.0]);
        assert_eq!(lowered, 2);
        // Companion: with a narrower share the 0.90 R ray counts as the limb's, and with only
        // the border kept the pair of the vertex next to it is lowered too.
        let mut obs2: Vec<Observation> = obs
            .iter()
            .map(|o| Observation { weight: 1.0, ..*o })
            .collect();
        let narrow = RimPairs {
            within: 0.85,
            border_rings: 0,
            ..prm
        };
        weigh(&m, &cams, &mut obs2, &narrow);
        let w2: Vec<f64> = obs2.iter().map(|o| o.weight).collect();
        assert_eq!(w2, [0.3, 1.0, 1.0, 1.0, 0.3, 1.0]);
        // A pair of a vertex the mesh does not have, or of a view there is none of, is left.
        let mut odd = vec![
            Observation {
                vertex: 10_000,
                ..obs[0]
            },
            Observation { view: 7, ..obs[0] },
        ];
        odd.iter_mut().for_each(|o| o.weight = 1.0);
        assert_eq!(weigh(&m, &cams, &mut odd, &prm), 0);
    }
}
