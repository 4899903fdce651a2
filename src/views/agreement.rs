//! What the views of one case must agree on before any work is done: one acetabulum spans about
//! as much in every view (`span_miss`) and lies where every view's outline points
//! (`centre_miss`). Case files (`case::CaseFile`) and a host's input (`pipeline::check_input`)
//! are held to both, each naming its own fields.
//!
//! Where the outlines point: each view's outline centre (the length-weighted centroid of its
//! annotated points) defines a ray from its source; for views whose poses and intrinsics belong
//! together these rays nearly meet, at the acetabulum. A view whose principal point, pose or
//! annotation belongs elsewhere sends its ray far past the point where the others meet, and no
//! shape can meet its outline: the solve then runs the template out of the views or bends a
//! view's pose by tens of millimetres to make it fit.

use crate::geom::{widest_extent, Curve};
use crate::views::Camera;
use nalgebra::{Matrix3, Point2, Point3, Vector3};
use std::cmp::Ordering;

/// How far a view's outline-centre ray may pass from the point where the other views' rays meet,
/// as a multiple of the acetabulum's span at the object (the views' median widest outline, mm).
/// Simulated from the 47 acetabula of ../shared/data (the paper's views, inlet and outlet views
/// turned 30 degrees about x, and views 45 degrees apart; levels 1 and 5; the ideal protocol and
/// the realistic one, with 1 degree and 2 mm pose errors, partial outlines and drift; 564 cases,
/// tests/case_agreement.rs): at most 0.34 (a02_rhip, inlet and outlet views, realistic). A
/// principal point given as 0 instead of the image centre, or an outline annotated 300 px off
/// (about 50 mm at the object), passes about one span off or more.
pub const MAX_CENTRE_MISS: f64 = 0.75;

/// A view's outline-centre ray: from its source through its outline's centre.
#[derive(Clone, Copy, Debug)]
struct CentreRay {
    view: usize,
    origin: Point3<f64>,
    dir: Vector3<f64>,
}

/// Where the views' outline centres disagree.
#[derive(Clone, Debug, PartialEq)]
pub enum CentreMiss {
    /// One view's ray passes `miss_mm` from where the others' meet (within `others_mm` of one
    /// another).
    View {
        /// The view.
        view: usize,
        /// How far its ray passes from the others' meeting point, mm.
        miss_mm: f64,
        /// The farthest the others' rays pass from it, mm.
        others_mm: f64,
        /// The acetabulum's span at the object (median over the views), mm.
        span_mm: f64,
    },
    /// The rays meet nowhere and no single view explains it (only two views have outlines, or
    /// several views could be the one off): the largest miss, mm (with two views, the gap
    /// between their rays).
    Views {
        /// The largest miss (or the gap), mm.
        miss_mm: f64,
        /// The acetabulum's span at the object, mm.
        span_mm: f64,
    },
}

/// The length-weighted centroid of a view's outlines (each segment at its midpoint, weighted by
/// its length, so a stretch clicked densely weighs no more than one clicked sparsely), or None
/// when they have no length.
fn outline_centre(curves: &[Curve]) -> Option<Point2<f64>> {
    let (mut sum, mut total) = (nalgebra::Vector2::zeros(), 0.0);
    for c in curves {
        let p = &c.points;
        let n = p.len();
        let segments = if c.closed { n } else { n.saturating_sub(1) };
        for i in 0..segments {
            let (a, b) = (p[i], p[(i + 1) % n]);
            let l = (b - a).norm();
            if l.is_finite() {
                sum += (a.coords + b.coords) * 0.5 * l;
                total += l;
            }
        }
    }
    (total > 0.0).then(|| Point2::from(sum / total))
}

/// The point nearest (least squares) to every ray, or None when they are (nearly) parallel.
fn meeting_point(rays: &[&CentreRay]) -> Option<Point3<f64>> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for r in rays {
        let m = Matrix3::identity() - r.dir * r.dir.transpose();
        a += m;
        b += m * r.origin.coords;
    }
    // Rays less than about a degree apart leave the depth along them undecided.
    let eig = a.symmetric_eigenvalues();
    if !(eig.min() > 1e-4 * eig.max()) {
        return None;
    }
    a.try_inverse().map(|inv| Point3::from(inv * b))
}

/// Distance from `p` to the ray.
fn miss(p: &Point3<f64>, r: &CentreRay) -> f64 {
    (p - r.origin).cross(&r.dir).norm()
}

/// The views' outline-centre rays (views without outline points left out) and the
/// acetabulum's span at the object: the median of each view's widest outline, in mm at the point
/// where all the rays meet (the depth the views themselves give, not a start's guess). None when
/// fewer than two views have outlines or their rays are parallel.
fn centre_rays(cams: &[Camera], observed: &[Vec<Curve>]) -> Option<(Vec<CentreRay>, f64)> {
    let mut rays = Vec::new();
    let mut widest = Vec::new();
    for (view, (cam, curves)) in cams.iter().zip(observed).enumerate() {
        let Some(c) = outline_centre(curves) else {
            continue;
        };
        let dir = cam.ray(&c);
        let px = curves
            .iter()
            .map(|cv| widest_extent(&cv.points))
            .fold(0.0, f64::max);
        if !(dir.iter().all(|v| v.is_finite()) && px.is_finite() && px > 0.0) {
            continue;
        }
        rays.push(CentreRay {
            view,
            origin: cam.center(),
            dir,
        });
        widest.push((cam, px));
    }
    if rays.len() < 2 {
        return None;
    }
    let at = meeting_point(&rays.iter().collect::<Vec<_>>())?;
    let mut spans: Vec<f64> = widest
        .iter()
        .map(|(cam, px)| px / cam.pixels_per_mm_at(&at))
        .collect();
    spans.sort_by(f64::total_cmp);
    let span_mm = 0.5 * (spans[(spans.len() - 1) / 2] + spans[spans.len() / 2]);
    (span_mm.is_finite() && span_mm > 0.0).then_some((rays, span_mm))
}

/// Each view's miss: how far its outline-centre ray passes from the point where the other
/// views' rays meet, and how far those pass from that point (their own spread), mm, with the
/// view's index among `rays`; None for a view whose others are parallel. With two views, each
/// one's miss is the gap between the two rays and the spread 0.
fn misses(rays: &[CentreRay]) -> Vec<(usize, f64, f64)> {
    if rays.len() == 2 {
        let at = meeting_point(&rays.iter().collect::<Vec<_>>());
        return at.map_or_else(Vec::new, |p| {
            let gap = miss(&p, &rays[0]) + miss(&p, &rays[1]);
            vec![(0, gap, 0.0), (1, gap, 0.0)]
        });
    }
    (0..rays.len())
        .filter_map(|k| {
            let others: Vec<&CentreRay> = rays
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != k)
                .map(|(_, r)| r)
                .collect();
            let p = meeting_point(&others)?;
            let spread = others.iter().map(|r| miss(&p, r)).fold(0.0, f64::max);
            Some((k, miss(&p, &rays[k]), spread))
        })
        .collect()
}

/// The largest miss of any view (`misses`) as a share of the acetabulum's span: what
/// `centre_miss` holds to `MAX_CENTRE_MISS`; None where `centre_miss` judges nothing.
pub fn centre_spread(cams: &[Camera], observed: &[Vec<Curve>]) -> Option<f64> {
    let (rays, span_mm) = centre_rays(cams, observed)?;
    let m = misses(&rays);
    (!m.is_empty()).then(|| m.iter().map(|x| x.1).fold(0.0, f64::max) / span_mm)
}

/// Whether the views' outline centres point at one place: every view's ray passes within
/// `MAX_CENTRE_MISS` spans of the point where the other views' rays meet. Where one does not,
/// which view sends its ray elsewhere (the one without which the others agree, if only one is).
/// Views without outline points are left out; None also when fewer than two views remain or
/// their rays are parallel (other checks refuse those).
pub fn centre_miss(cams: &[Camera], observed: &[Vec<Curve>]) -> Option<CentreMiss> {
    let (rays, span_mm) = centre_rays(cams, observed)?;
    let limit = MAX_CENTRE_MISS * span_mm;
    let all = misses(&rays);
    let worst = all.iter().map(|x| x.1).fold(0.0, f64::max);
    if worst <= limit {
        return None;
    }
    // The view without which the others agree: far off itself, the others within a quarter of
    // the bound of their own meeting point, and without any other view the rest still apart by
    // half the bound or more. Views all turned about one axis, as the paper's, have their rays
    // in about one plane, where any two meet: a view off within that plane cannot be told from
    // the others, and all are named.
    let mut by_spread: Vec<&(usize, f64, f64)> = all.iter().collect();
    by_spread.sort_by(|a, b| a.2.total_cmp(&b.2));
    Some(match by_spread[..] {
        [&(k, miss_mm, others_mm), next, ..]
            if rays.len() >= 3
                && miss_mm > limit
                && others_mm <= 0.25 * limit
                && next.2 >= 0.5 * limit =>
        {
            CentreMiss::View {
                view: rays[k].view,
                miss_mm,
                others_mm,
                span_mm,
            }
        }
        _ => CentreMiss::Views {
            miss_mm: worst,
            span_mm,
        },
    })
}

/// One acetabulum is seen in every view, so its closed outlines span about as much at the object
/// in each: a view's widest closed outline may span from half to twice the median of the other
/// views' (in mm at the template's centre). The outlines simulated from the 78 acetabula of
/// docs/population.md (levels 1 and 5, five draws each) span at least 0.75 of the widest view's
/// with the default views (0 and +-20 degrees about z), 0.71 with inlet and outlet views (x
/// +-30), and 0.56 with views 45-60 degrees apart: a bound for outlines at a wrong scale (a
/// tiny one, one in millimetres instead of pixels) and a view's k off by a factor, not for
/// small disagreements (the outline guard is for those).
pub const MAX_OUTLINE_SPAN_RATIO: f64 = 2.0;

/// The view whose widest outline spans least like the others' (`span_miss`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpanMiss {
    /// The view.
    pub view: usize,
    /// Its widest outline (closed ones first).
    pub contour: usize,
    /// That outline's widest extent, px.
    pub px: f64,
    /// The same in mm at the object.
    pub mm: f64,
    /// The median of the other views' widest outlines, mm at the object.
    pub median_mm: f64,
}

/// The view whose outline spans least like the others' (`MAX_OUTLINE_SPAN_RATIO`), if any;
/// `px_per_mm` is each view's scale at the object (`Camera::pixels_per_mm_at`). Each view is
/// measured by its widest closed outline; a view with open ones only, by its widest arc, which is
/// a lower bound of the rim's span: it counts among the others, and is itself refused only for
/// spanning too much. None with fewer than two views with outlines.
pub fn span_miss(observed: &[Vec<Curve>], px_per_mm: &[f64]) -> Option<SpanMiss> {
    /// A view's widest outline: where it is, its span in px and in mm at the object.
    struct Span {
        view: usize,
        contour: usize,
        px: f64,
        mm: f64,
        closed: bool,
    }
    // Each view's widest outline, closed ones first.
    let spans: Vec<Span> = observed
        .iter()
        .zip(px_per_mm)
        .enumerate()
        .filter_map(|(view, (curves, &px_per_mm))| {
            curves
                .iter()
                .enumerate()
                .map(|(contour, c)| {
                    let px = widest_extent(&c.points);
                    Span {
                        view,
                        contour,
                        px,
                        mm: px / px_per_mm,
                        closed: c.closed,
                    }
                })
                .max_by(|a, b| {
                    (a.closed, a.mm)
                        .partial_cmp(&(b.closed, b.mm))
                        .unwrap_or(Ordering::Equal)
                })
        })
        .collect();
    if spans.len() < 2 {
        return None;
    }
    // (how far off, as |ln ratio|, the others' median) of view k when it is off.
    let off = |k: usize| {
        let mut others: Vec<f64> = spans
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != k)
            .map(|(_, s)| s.mm)
            .collect();
        others.sort_by(f64::total_cmp);
        let m = others.len();
        let median = 0.5 * (others[(m - 1) / 2] + others[m / 2]);
        let r = spans[k].mm / median;
        let too_small = spans[k].closed && r < 1.0 / MAX_OUTLINE_SPAN_RATIO;
        (too_small || r > MAX_OUTLINE_SPAN_RATIO || !r.is_finite())
            .then_some((r.ln().abs(), median))
    };
    // The view farthest off (the first of equals; a NaN distance never displaces one).
    let (k, (_, median_mm)) = (0..spans.len())
        .filter_map(|k| off(k).map(|o| (k, o)))
        .reduce(|best, x| if x.1 .0 > best.1 .0 { x } else { best })?;
    let s = &spans[k];
    Some(SpanMiss {
        view: s.view,
        contour: s.contour,
        px: s.px,
        mm: s.mm,
        median_mm,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_centre_is_weighted_by_length_not_by_clicks() {
        // A square clicked densely along one side has its centre in the middle all the same.
        let mut points: Vec<Point2<f64>> =
            (0..50).map(|i| Point2::new(i as f64 * 2.0, 0.0)).collect();
        points.extend([
            Point2::new(100.0, 0.0),
            Point2::new(100.0, 100.0),
            Point2::new(0.0, 100.0),
        ]);
        let c = outline_centre(&[Curve {
            points: points.clone(),
            closed: true,
        }])
        .unwrap();
        assert!((c - Point2::new(50.0, 50.0)).norm() < 1e-9, "{c}");
        // The companion: the mean of the clicks lies near the dense side.
        let mean = points
            .iter()
            .fold(nalgebra::Vector2::zeros(), |s, p| s + p.coords)
            / points.len() as f64;
        assert!(mean.y < 10.0, "{mean}");
    }
}
