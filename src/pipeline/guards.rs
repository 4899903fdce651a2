//! Guards on a result: what the method cannot stand behind is caught before it is returned. A
//! reconstruction that folds over, leaves the sphere its outlines' limbs define, has a cup no
//! acetabulum has, ends far from its outlines, or is crumpled is a `GuardFailure`;
//! `reconstruct` then falls back (see `Fallback`) and reports which fallback it took, or fails
//! with the reason.

use crate::contours::ModelContour;
use crate::geom::{Curve, Mesh, Segments, Sphere};
use serde::Serialize;

/// The guards' limits, with their defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct GuardParams {
    /// The cup's diameter must lie in this range, mm (default 30-80: every adult acetabulum
    /// and every cup catalogue).
    pub cup_range_mm: (f64, f64),
    /// Largest share of triangles facing the sphere's centre (folded over; default 0.1: the
    /// template has none, good results 0-0.1 %, the srvf sheets that caused the catastrophes
    /// 49-55 %, while the baselines' usable results reach 3-9 % at a curled rim; smaller folds
    /// that come with a bad fit are caught by the reprojection guard). Above
    /// `PlacementParams::restart_above_folded` (2 %) a result restarts from tilted starts first.
    pub max_folded: f64,
    /// With a limb sphere: the cup sphere's centre within this fraction of the limb radius of
    /// the limb centre, and its radius within this fraction of the limb radius (default 0.25).
    pub max_limb_offset: f64,
    /// Largest reprojection RMS of the last correspondences, pixels (default 10; 2 px
    /// annotation noise ends at 1-3 px).
    pub max_rms_px: f64,
    /// Largest distance of the result's outlines from the annotations (`SolveLog::outline_px`,
    /// the RMS over all views), pixels (default 5). Measured on the 47 acetabula of
    /// ../shared/data (srvf, levels 1, 3, 5 x 3 runs, seed 7): with exact poses at most 3.5 px,
    /// whether the annotation has 2 px of noise, 4 px, or 4 px of drift with clicks 30 px apart
    /// (16 of them, levels 3 and 5 x 2 runs, for the last two); with the realistic protocol's
    /// pose errors (1 degree, 2 mm) and pose refinement at most 4.5 px but for two runs at 6.8
    /// and 7.6 px, cups 9.8 and 5.3 mm off; without refinement a quarter of the runs end above
    /// 5 px, and refining their poses takes their cup RMS error from 6.2 to 3.5 mm. Above it
    /// the views' poses or outlines do not agree on one shape (`Fallback::RefinePoses`).
    pub max_outline_px: f64,
    /// Largest RMS distance from the cup sphere of the part of the surface it is fitted to, mm
    /// (default 3.5). Measured on the 47 acetabula of ../shared/data (levels 1, 3, 5 x 3 runs,
    /// seed 7): at most 2.0 mm for srvf with ideal X-rays, 2.4 mm for the baselines, 2.8 mm
    /// under the realistic protocol with pose refinement but for two runs 5-6 mm off (3.2 and
    /// 4.0 mm); 4.5-5.5 mm for the example case with annotations given to the wrong views, a
    /// crumpled surface whose outlines still lie within 3.5 px of the annotations. Above it the
    /// cup sphere stands for no socket.
    pub max_sphere_rms_mm: f64,
    /// Smallest share of the result's own outline, in the view where it is largest, that lies
    /// along an annotation (`annotated_shares`; default 0.45). Left open (an annotation that
    /// leaves out the rim over the femoral head) the cap can grow into the gaps, and its outline
    /// with it, where nothing holds it. Measured on the 47 acetabula of ../shared/data (srvf,
    /// realistic protocol with only the 2 px jitter, levels 1, 3, 5 x 2 runs, seed 7): 0.94 or
    /// more with whole outlines; 0.50-0.80 with a quarter of each left out (the realistic
    /// protocol's share), and 0.50-0.77 under the whole realistic protocol; 0.41-0.66 with 40 %
    /// left out and 0.30-0.55 with half, where 155 of 282 cups are more than 5 mm off. Below it
    /// the annotations leave the cup's size open, and the run fails without restarts or
    /// fallbacks (`Fallback::order`), which bent such results past it still off.
    pub min_annotated_share: f64,
}

impl Default for GuardParams {
    fn default() -> Self {
        GuardParams {
            cup_range_mm: (30.0, 80.0),
            max_folded: 0.1,
            max_limb_offset: 0.25,
            max_rms_px: 10.0,
            max_outline_px: 5.0,
            max_sphere_rms_mm: 3.5,
            min_annotated_share: 0.45,
        }
    }
}

impl GuardParams {
    /// Whether a cup of diameter `d` mm is one the guards take (`cup_range_mm`, ends included;
    /// NaN is not): the cup guard's test, which the cup report's resamples are held to as well.
    pub fn holds_cup(&self, d: f64) -> bool {
        let (lo, hi) = self.cup_range_mm;
        d >= lo && d <= hi
    }
}

/// Why a result was not returned as it stood.
#[derive(Clone, Debug, PartialEq, Serialize, thiserror::Error)]
#[serde(tag = "guard", rename_all = "kebab-case")]
#[non_exhaustive]
pub enum GuardFailure {
    /// The cup's diameter is outside what an acetabulum has.
    #[error("cup diameter {diameter_mm:.1} mm is outside {lo:.0}-{hi:.0} mm")]
    Cup {
        /// The diameter, mm.
        diameter_mm: f64,
        /// The range's lower end, mm.
        lo: f64,
        /// Its upper end, mm.
        hi: f64,
    },
    /// The surface folds over.
    #[error("{:.1} % of the surface's triangles face the cup's centre (folded over)", 100.0 * .folded)]
    Folded {
        /// Share of the triangles facing the centre.
        folded: f64,
    },
    /// The surface lies far from its own cup sphere: crumpled, not a socket.
    #[error(
        "the observed surface lies {rms_mm:.1} mm RMS from its cup sphere (above {max_mm:.1} \
         mm): it is crumpled, as when an annotation is given to the wrong view"
    )]
    Rough {
        /// The RMS distance from the cup sphere of the part of the surface it was fitted to
        /// (`Sphere::rms`), mm.
        rms_mm: f64,
        /// The limit, mm.
        max_mm: f64,
    },
    /// The cup sphere left the limb sphere behind.
    #[error(
        "the cup sphere (radius {radius_mm:.1} mm) lies {offset_mm:.1} mm from the outlines' \
         limb sphere (radius {limb_radius_mm:.1} mm): the surface does not stand on the \
         outlines, as when an annotation is given to the wrong view"
    )]
    LimbSphere {
        /// Distance between the centres, mm.
        offset_mm: f64,
        /// The cup sphere's radius, mm.
        radius_mm: f64,
        /// The limb sphere's radius, mm.
        limb_radius_mm: f64,
    },
    /// A solve left a vertex NaN or infinite.
    #[error("the solver diverged: vertex {vertex} is not finite")]
    NonFiniteVertex {
        /// The first such vertex.
        vertex: usize,
    },
    /// A pose refinement left a view's correction NaN or infinite.
    #[error("the solver diverged: the pose correction of view {view} is not finite")]
    NonFinitePose {
        /// The view.
        view: usize,
    },
    /// The result ends far from its outlines.
    #[error("reprojection RMS {rms_px:.1} px is above {max_px:.0} px")]
    Reprojection {
        /// The RMS, pixels.
        rms_px: f64,
        /// The limit, pixels.
        max_px: f64,
    },
    /// The result's outlines lie far from the annotations: no one shape meets every view as
    /// its pose says.
    #[error(
        "the result's outlines lie {outline_px:.1} px from the annotations (above {max_px:.0} \
         px): the views' poses and outlines do not agree on one shape"
    )]
    Outlines {
        /// The RMS distance, pixels (`SolveLog::outline_px`).
        outline_px: f64,
        /// The limit, pixels.
        max_px: f64,
    },
    /// The annotations leave so much of the rim open that the result's outline runs along
    /// them over too little of its length in every view: the cap grew into the gaps.
    #[error(
        "the result's outline lies along the annotations over {:.0} % of its length in its \
         best view (below {:.0} %): the annotations leave so much of the rim open that the cap \
         grew into the gaps, and the cup with it; annotate more of the rim in at least one view",
        100.0 * .share, 100.0 * .min
    )]
    OpenRims {
        /// The largest share over the views (`SolveLog::annotated_share`).
        share: f64,
        /// The limit.
        min: f64,
    },
}

impl GuardFailure {
    /// The guard's name, as report.json's `guard` tag and runs.csv's cause columns write it:
    /// "cup", "folded", "rough", "limb-sphere", "non-finite-vertex", "non-finite-pose",
    /// "reprojection", "outlines" or "open-rims".
    pub fn name(&self) -> &'static str {
        match self {
            GuardFailure::Cup { .. } => "cup",
            GuardFailure::Folded { .. } => "folded",
            GuardFailure::Rough { .. } => "rough",
            GuardFailure::LimbSphere { .. } => "limb-sphere",
            GuardFailure::NonFiniteVertex { .. } => "non-finite-vertex",
            GuardFailure::NonFinitePose { .. } => "non-finite-pose",
            GuardFailure::Reprojection { .. } => "reprojection",
            GuardFailure::Outlines { .. } => "outlines",
            GuardFailure::OpenRims { .. } => "open-rims",
        }
    }
}

/// Share of the triangles of `mesh` whose outward normal faces `sphere`'s centre.
pub fn folded_share(mesh: &Mesh, sphere: &Sphere) -> f64 {
    let c = sphere.center_point();
    let n = mesh.triangles.len();
    if n == 0 {
        return 0.0;
    }
    let folded = mesh
        .triangles
        .iter()
        .filter(|t| {
            let [a, b, d] = t.map(|i| mesh.vertices[i as usize]);
            let normal = (b - a).cross(&(d - a));
            let mid = (a.coords + b.coords + d.coords) / 3.0;
            normal.dot(&(mid - c.coords)) < 0.0
        })
        .count();
    folded as f64 / n as f64
}

/// What the guards judge of one result besides its surface: its cup sphere, the limb sphere
/// (centre and radius) when one was fitted, its final reprojection RMS and its outlines'
/// distance from the annotations (pixels).
#[derive(Clone, Copy, Debug)]
pub struct Judged<'a> {
    /// The result's surface.
    pub mesh: &'a Mesh,
    /// Its cup sphere.
    pub cup: &'a Sphere,
    /// The outlines' limb sphere, when one was fitted.
    pub limb: Option<[f64; 4]>,
    /// The reprojection RMS of the last correspondences, pixels.
    pub rms_px: f64,
    /// The outlines' distance from the annotations (`SolveLog::outline_px`), pixels.
    pub outline_px: f64,
    /// The share of its outline along the annotations in its best view
    /// (`SolveLog::annotated_share`).
    pub annotated_share: f64,
}

/// The first guard the result fails, or None.
pub fn first_failure(g: &GuardParams, judged: &Judged) -> Option<GuardFailure> {
    let Judged {
        mesh,
        cup,
        limb,
        rms_px,
        outline_px,
        annotated_share,
    } = *judged;
    let d = cup.diameter();
    let (lo, hi) = g.cup_range_mm;
    if !g.holds_cup(d) {
        return Some(GuardFailure::Cup {
            diameter_mm: d,
            lo,
            hi,
        });
    }
    let folded = folded_share(mesh, cup);
    if folded > g.max_folded {
        return Some(GuardFailure::Folded { folded });
    }
    // A crumpled surface whose outlines are met is named as crumpled before the limb sphere and
    // the reprojection are judged: its cup sphere is no socket's, and its fallbacks must not
    // refine the poses (`Fallback::order`; the phantom with two views' annotations swapped,
    // whose cup fitted to one point per pair left the limb sphere too). One both crumpled and
    // far from its outlines (or with no outline distance) fails the outlines below, whose
    // fallback refines the poses first.
    if !(cup.rms <= g.max_sphere_rms_mm) && outline_px <= g.max_outline_px {
        return Some(GuardFailure::Rough {
            rms_mm: cup.rms,
            max_mm: g.max_sphere_rms_mm,
        });
    }
    if let Some([x, y, z, r]) = limb {
        let offset = (cup.center_point() - nalgebra::Point3::new(x, y, z)).norm();
        if offset > g.max_limb_offset * r || (cup.radius - r).abs() > g.max_limb_offset * r {
            return Some(GuardFailure::LimbSphere {
                offset_mm: offset,
                radius_mm: cup.radius,
                limb_radius_mm: r,
            });
        }
    }
    if !(rms_px <= g.max_rms_px) {
        return Some(GuardFailure::Reprojection {
            rms_px,
            max_px: g.max_rms_px,
        });
    }
    if !(outline_px <= g.max_outline_px) {
        return Some(GuardFailure::Outlines {
            outline_px,
            max_px: g.max_outline_px,
        });
    }
    if !(annotated_share >= g.min_annotated_share) {
        return Some(GuardFailure::OpenRims {
            share: annotated_share,
            min: g.min_annotated_share,
        });
    }
    None
}

/// A model outline point lies along an annotation when it is within this of it, pixels (twice
/// the 2 px annotation noise the method is measured with).
pub const ALONG_PX: f64 = 4.0;

/// Per view, the share of the length of the model outline (`model_contours`, one closed
/// outline a view, as a result's `final_contours`) whose segments' midpoints lie within
/// `ALONG_PX` of the view's open arcs (`observed`): less than 1 where they leave part of the rim
/// open and the outline runs on there. 1 for a view annotated all the way round (a closed
/// outline: how near the result lies to it is the outline guard's to judge, so noisier
/// annotations on larger images are not read as open); 0 for a view without a model outline.
pub fn annotated_shares(model_contours: &[ModelContour], observed: &[Vec<Curve>]) -> Vec<f64> {
    observed
        .iter()
        .enumerate()
        .map(|(view, curves)| {
            if curves.iter().any(|c| c.closed) {
                return 1.0;
            }
            let Some(model) = model_contours.get(view).filter(|m| m.points.len() >= 2) else {
                return 0.0;
            };
            let near: Vec<Segments> = curves
                .iter()
                .map(|c| Segments::new(&c.points, false))
                .collect();
            let p = &model.points;
            let (mut all, mut along) = (0.0, 0.0);
            for (i, a) in p.iter().enumerate() {
                let b = p[(i + 1) % p.len()];
                let len = (b - a).norm();
                let mid = nalgebra::Point2::from((a.coords + b.coords) * 0.5);
                all += len;
                if near.iter().any(|s| s.distance(&mid) <= ALONG_PX) {
                    along += len;
                }
            }
            if all > 0.0 {
                along / all
            } else {
                0.0
            }
        })
        .collect()
}

/// `SolveLog::view_note`: a view is named when its outline distance is above this (pixels) ...
pub const VIEW_NOTE_MIN_PX: f64 = 3.0;
/// ... and this many times the worst of the other views'.
pub const VIEW_NOTE_RATIO: f64 = 2.0;

/// The view whose outline lies far worse than the others' (more than `VIEW_NOTE_MIN_PX` and
/// `VIEW_NOTE_RATIO` times the worst of the rest), from the per-view outline distances: (view,
/// its distance, the worst of the rest). None when the views agree or a distance is not finite.
pub fn odd_view(d: &[f64]) -> Option<(usize, f64, f64)> {
    if d.len() < 2 || d.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let (worst, &px) = d.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    let rest = d
        .iter()
        .enumerate()
        .filter(|&(k, _)| k != worst)
        .map(|(_, &x)| x)
        .fold(0.0_f64, f64::max);
    (px > VIEW_NOTE_MIN_PX && px > VIEW_NOTE_RATIO * rest).then_some((worst, px, rest))
}

/// How a message names view `k`: "view k (its name)", or "view k" where `names` has none.
pub fn view_label(names: &[String], k: usize) -> String {
    names
        .get(k)
        .map_or(format!("view {k}"), |n| format!("view {k} ({n})"))
}

/// A result the guards refused after every fallback: the first failure (the method as asked
/// for), and how far each view's outline lay from its annotation in that result. The message
/// gives those distances, and names a view far off the others (`odd_view`): where one view's
/// annotation or pose is wrong, its distance is usually the largest.
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    /// The guard the method as asked for failed.
    pub failure: GuardFailure,
    /// That result's `SolveLog::outline_px_per_view` (empty when it had none, as when its
    /// vertices were not finite).
    pub outline_px_per_view: Vec<f64>,
    /// The views' names, where the caller knows them (a case file); else "view k" alone.
    pub names: Vec<String>,
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.failure)?;
        let d = &self.outline_px_per_view;
        if d.is_empty() || d.iter().any(|x| !x.is_finite()) {
            return Ok(());
        }
        let name = |k: usize| view_label(&self.names, k);
        let each: Vec<String> = d
            .iter()
            .enumerate()
            .map(|(k, px)| format!("{} {px:.1} px", name(k)))
            .collect();
        write!(
            f,
            "; its outlines lay from the annotations: {}",
            each.join(", ")
        )?;
        if let Some((k, _, _)) = odd_view(d) {
            write!(
                f,
                "; {} is far off the others: check its annotation and pose",
                name(k)
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::fit_sphere;
    use crate::template::hemisphere;
    use nalgebra::Point2;

    /// A refusal gives each view's outline distance and names the view far off the others (the
    /// example case's AP rim scaled to half: 21.1 px against 5.5 and 7.6), by its name where it
    /// has one. Companions: views within a factor of two of each other name none; a distance
    /// that is not finite, or none, leave the failure's message alone.
    #[test]
    fn a_refusal_gives_the_views_outline_distances_and_names_one_far_off() {
        let failure = GuardFailure::Cup {
            diameter_mm: 200.4,
            lo: 30.0,
            hi: 80.0,
        };
        let refusal = |d: &[f64], names: &[&str]| {
            Refusal {
                failure: failure.clone(),
                outline_px_per_view: d.to_vec(),
                names: names.iter().map(|n| n.to_string()).collect(),
            }
            .to_string()
        };
        assert_eq!(
            refusal(&[21.1, 5.5, 7.6], &["AP", "+20", "-20"]),
            format!(
                "{failure}; its outlines lay from the annotations: view 0 (AP) 21.1 px, view 1 \
                 (+20) 5.5 px, view 2 (-20) 7.6 px; view 0 (AP) is far off the others: check its \
                 annotation and pose"
            )
        );
        assert!(refusal(&[2.0, 9.0, 3.0], &[]).ends_with(
            "view 0 2.0 px, view 1 9.0 px, view 2 3.0 px; view 1 is far off the others: check \
             its annotation and pose"
        ));
        assert_eq!(
            refusal(&[16.5, 8.2, 10.1], &["AP", "+20", "-20"]),
            format!(
                "{failure}; its outlines lay from the annotations: view 0 (AP) 16.5 px, view 1 \
                 (+20) 8.2 px, view 2 (-20) 10.1 px"
            )
        );
        for d in [&[21.1, f64::NAN, 7.6][..], &[]] {
            assert_eq!(refusal(d, &["AP"]), failure.to_string(), "{d:?}");
        }
    }

    /// Each guard's name is the tag report.json writes for it, and no two guards share one
    /// (companion: a name taken from another guard's tag does not match).
    #[test]
    fn a_guards_name_is_its_report_tag() {
        let all = [
            GuardFailure::Cup {
                diameter_mm: 90.0,
                lo: 30.0,
                hi: 80.0,
            },
            GuardFailure::Folded { folded: 0.2 },
            GuardFailure::Rough {
                rms_mm: 4.0,
                max_mm: 3.5,
            },
            GuardFailure::LimbSphere {
                offset_mm: 9.0,
                radius_mm: 25.0,
                limb_radius_mm: 24.0,
            },
            GuardFailure::NonFiniteVertex { vertex: 3 },
            GuardFailure::NonFinitePose { view: 1 },
            GuardFailure::Reprojection {
                rms_px: 9.0,
                max_px: 8.0,
            },
            GuardFailure::Outlines {
                outline_px: 6.0,
                max_px: 5.0,
            },
            GuardFailure::OpenRims {
                share: 0.3,
                min: 0.45,
            },
        ];
        let tag = |g: &GuardFailure| serde_json::to_value(g).unwrap()["guard"].clone();
        for g in &all {
            assert_eq!(tag(g), g.name(), "{g:?}");
        }
        let names: std::collections::BTreeSet<&str> = all.iter().map(|g| g.name()).collect();
        assert_eq!(names.len(), all.len());
        assert_ne!(tag(&all[0]), all[1].name());
    }

    #[test]
    fn each_guard_catches_its_failure_and_passes_a_good_cup() {
        let g = GuardParams::default();
        let m = hemisphere(26.0, 800);
        let s = fit_sphere(&m.vertices).unwrap();
        let limb = Some([s.center[0], s.center[1], s.center[2], s.radius]);
        let judge_open = |mesh: &Mesh, cup: &Sphere, limb, rms_px, outline_px, annotated_share| {
            first_failure(
                &g,
                &Judged {
                    mesh,
                    cup,
                    limb,
                    rms_px,
                    outline_px,
                    annotated_share,
                },
            )
        };
        let judge = |mesh: &Mesh, cup: &Sphere, limb, rms_px, outline_px| {
            judge_open(mesh, cup, limb, rms_px, outline_px, 1.0)
        };
        // Companion: the hemisphere itself passes every guard.
        assert_eq!(judge(&m, &s, limb, 2.0, 1.5), None);
        assert_eq!(judge(&m, &s, limb, 2.0, 5.0), None);
        assert_eq!(folded_share(&m, &s), 0.0);
        // A flat sheet: a cup of metres.
        let big = Sphere { radius: 400.0, ..s };
        assert!(matches!(
            judge(&m, &big, None, 2.0, 1.5),
            Some(GuardFailure::Cup { .. })
        ));
        // The surface turned inside out: every triangle faces the centre.
        let mut inside_out = m.clone();
        for t in &mut inside_out.triangles {
            t.swap(1, 2);
        }
        assert!(matches!(
            judge(&inside_out, &s, limb, 2.0, 1.5),
            Some(GuardFailure::Folded { .. })
        ));
        // A crumpled surface: its cup sphere fits it to 4 mm RMS; 3 mm passes.
        for (rms, rough) in [(4.0, true), (3.0, false), (f64::NAN, true)] {
            let c = Sphere { rms, ..s };
            assert_eq!(
                matches!(
                    judge(&m, &c, limb, 2.0, 1.5),
                    Some(GuardFailure::Rough { .. })
                ),
                rough,
                "{rms}"
            );
        }
        // A cup 10 mm off the limb sphere.
        let off = Sphere {
            center: [s.center[0] + 10.0, s.center[1], s.center[2]],
            ..s
        };
        assert!(matches!(
            judge(&m, &off, limb, 2.0, 1.5),
            Some(GuardFailure::LimbSphere { .. })
        ));
        // Far from the outlines.
        assert!(matches!(
            judge(&m, &s, limb, 25.0, 1.5),
            Some(GuardFailure::Reprojection { .. })
        ));
        assert!(matches!(
            judge(&m, &s, limb, f64::NAN, 1.5),
            Some(GuardFailure::Reprojection { .. })
        ));
        // Outlines the result does not meet.
        assert_eq!(
            judge(&m, &s, limb, 5.0, 5.5),
            Some(GuardFailure::Outlines {
                outline_px: 5.5,
                max_px: 5.0
            })
        );
        assert!(matches!(
            judge(&m, &s, limb, 5.0, f64::NAN),
            Some(GuardFailure::Outlines { .. })
        ));
        // A crumpled surface whose cup sphere also left the limb sphere, or whose reprojection
        // is also off: with its outlines met it is named crumpled, since its cup sphere is no
        // socket's (and its fallbacks must not refine the poses).
        let crumpled_off = Sphere { rms: 4.0, ..off };
        assert!(matches!(
            judge(&m, &crumpled_off, limb, 2.0, 1.5),
            Some(GuardFailure::Rough { .. })
        ));
        let crumpled = Sphere { rms: 4.0, ..s };
        assert!(matches!(
            judge(&m, &crumpled, limb, 25.0, 1.5),
            Some(GuardFailure::Rough { .. })
        ));
        // Companion: with its outlines not met as well, the outlines are named (their
        // fallback refines the poses first).
        assert!(matches!(
            judge(&m, &crumpled, limb, 2.0, 5.5),
            Some(GuardFailure::Outlines { .. })
        ));
        // A result whose outline runs along the annotations over too little of its length; at
        // the limit and above it passes (companion), and a share that is not a number fails.
        assert_eq!(
            judge_open(&m, &s, limb, 2.0, 1.5, 0.40),
            Some(GuardFailure::OpenRims {
                share: 0.40,
                min: 0.45
            })
        );
        for (share, open) in [(0.45, false), (0.6, false), (f64::NAN, true)] {
            assert_eq!(
                matches!(
                    judge_open(&m, &s, limb, 2.0, 1.5, share),
                    Some(GuardFailure::OpenRims { .. })
                ),
                open,
                "{share}"
            );
        }
        // Outlines not met are named first (their fallback refines the poses).
        assert!(matches!(
            judge_open(&m, &s, limb, 2.0, 5.5, 0.3),
            Some(GuardFailure::Outlines { .. })
        ));
    }

    /// A circle's outline (radius 100 px, 200 points) against annotations of it: whole and
    /// closed (1, even 10 px off: that is the outline guard's), an arc over 60 % of it (0.6, and
    /// a little more: a model point within `ALONG_PX` of an arc's end counts), and an arc all
    /// the way round but 10 px off (0). Companion: the share does not read the arc's 60 % as
    /// the whole.
    #[test]
    fn the_annotated_share_is_the_outline_length_along_the_annotation() {
        let circle = |r: f64, n: usize, from: f64, share: f64| -> Vec<Point2<f64>> {
            (0..n)
                .map(|i| {
                    let t = from + std::f64::consts::TAU * share * i as f64 / n as f64;
                    Point2::new(500.0 + r * t.cos(), 400.0 + r * t.sin())
                })
                .collect()
        };
        let model = vec![ModelContour {
            vertex_ids: (0..200).collect(),
            points: circle(100.0, 200, 0.0, 1.0),
        }];
        let curve = |points, closed| vec![vec![Curve { points, closed }]];
        let share = |obs: &[Vec<Curve>]| annotated_shares(&model, obs)[0];
        assert!((share(&curve(circle(101.0, 73, 0.3, 1.0), true)) - 1.0).abs() < 1e-9);
        let arc = circle(101.0, 60, 1.0, 0.6 * 60.0 / 59.0);
        assert!((share(&curve(arc.clone(), false)) - 0.6).abs() < 0.02);
        assert_eq!(share(&curve(circle(110.0, 73, 0.3, 1.0), true)), 1.0);
        assert!(share(&curve(circle(110.0, 73, 0.3, 1.0), false)) < 1e-9);
        // Two arcs of one rim count together; a view without a model outline counts 0.
        let two = vec![vec![
            Curve {
                points: circle(100.0, 30, 0.0, 0.3 * 30.0 / 29.0),
                closed: false,
            },
            Curve {
                points: circle(100.0, 30, 3.0, 0.3 * 30.0 / 29.0),
                closed: false,
            },
        ]];
        assert!((share(&two) - 0.6).abs() < 0.03, "{}", share(&two));
        assert_eq!(annotated_shares(&[], &curve(arc.clone(), false)), vec![0.0]);
        assert!((share(&curve(arc, false)) - 1.0).abs() > 0.3);
    }
}
