//! The case's views checked against one another once they are read, each failure named by its
//! field for the case file's error: one acetabulum spans about as much in every view
//! (`outline_span_mismatch`, on `views::span_miss`) and lies where every view's outline points
//! (`outline_centre_mismatch`, on `views::centre_miss`).

use crate::geom::Curve;
use crate::views::MAX_OUTLINE_SPAN_RATIO;
use crate::views::{centre_miss, span_miss, Camera, CentreMiss, SpanMiss};

/// Where the views disagree, as the case's error names it (`file::field_err`).
pub(super) struct Disagreement {
    pub(super) field: String,
    pub(super) value: String,
    pub(super) reason: String,
}

/// What the checks read of a case's views, in view order: the views' names, cameras, outlines,
/// and pixels per mm at the object.
pub(super) struct Views<'a> {
    pub(super) names: &'a [String],
    pub(super) cameras: &'a [Camera],
    pub(super) observed: &'a [Vec<Curve>],
    pub(super) px_per_mm: &'a [f64],
}

/// The view whose outline spans least like the others' (`views::span_miss`), as an error naming
/// it, if any.
pub(super) fn outline_span_mismatch(case: &Views) -> Option<Disagreement> {
    let SpanMiss {
        view,
        contour,
        px,
        mm,
        median_mm,
    } = span_miss(case.observed, case.px_per_mm)?;
    Some(disagreement(
        format!("views[{view}].contours[{contour}].points"),
        format!(
            "an outline of view {} spanning {mm:.1} mm at the object ({px:.0} px), against \
             {median_mm:.1} mm in the other views",
            case.names[view]
        ),
        format!(
            "one acetabulum spans about as much in every view (from 1/{MAX_OUTLINE_SPAN_RATIO:.0} \
             to {MAX_OUTLINE_SPAN_RATIO:.0} times the others'): is this outline annotated at \
             another scale, or are this view's k (focal length) or t wrong?"
        ),
    ))
}

/// The views' outline centres pointing at no one place (`agreement::centre_miss`), as an error
/// naming the view that sends its ray elsewhere, or all of them when no one view explains it.
pub(super) fn outline_centre_mismatch(case: &Views) -> Option<Disagreement> {
    let reason = "one acetabulum lies where every view's outline points (each view's ray through \
                  its outline's centre passes within 3/4 of the acetabulum's span of where the \
                  others meet)";
    Some(match centre_miss(case.cameras, case.observed)? {
        CentreMiss::View {
            view,
            miss_mm,
            others_mm,
            span_mm,
        } => disagreement(
            format!("views[{view}].contours"),
            format!(
                "an outline whose centre's ray passes {miss_mm:.0} mm from where the other \
                 views' outlines point (they agree within {others_mm:.0} mm; the acetabulum \
                 spans {span_mm:.0} mm)"
            ),
            format!(
                "{reason}: are view {}'s k (cx, cy), r or t wrong, or is its outline annotated \
                 on another image?",
                case.names[view]
            ),
        ),
        CentreMiss::Views { miss_mm, span_mm } => disagreement(
            "views[*].contours",
            format!(
                "outlines whose centres' rays pass up to {miss_mm:.0} mm from where they meet \
                 (the acetabulum spans {span_mm:.0} mm)"
            ),
            format!(
                "{reason}: the views' poses (r, t), principal points (cx, cy) or outlines do \
                 not belong to one acetabulum (which view is off cannot be told where any two \
                 of the rays meet, as for views all turned about one axis and off across it)"
            ),
        ),
    })
}

/// A `Disagreement` from its three parts.
fn disagreement(
    field: impl Into<String>,
    value: impl Into<String>,
    reason: impl Into<String>,
) -> Disagreement {
    Disagreement {
        field: field.into(),
        value: value.into(),
        reason: reason.into(),
    }
}

#[cfg(test)]
mod tests {
    use crate::sim::{phantom, simulate_case, NoiseLevel, PhantomParams, SimCase, XrayGeometry};
    use crate::views::{centre_miss, centre_spread, CentreMiss, MAX_CENTRE_MISS};

    fn phantom_case(seed: u64) -> SimCase {
        let truth = phantom(&PhantomParams::default()).mesh;
        let level = NoiseLevel::level(3).unwrap();
        simulate_case(&truth, &XrayGeometry::default(), 2.0, &level, seed).unwrap()
    }

    #[test]
    fn the_views_of_a_simulated_case_point_at_one_place() {
        for seed in 1..4 {
            let case = phantom_case(seed);
            let spread = centre_spread(&case.cameras, &case.observed).unwrap();
            assert!(spread < 0.1, "seed {seed}: {spread}");
            assert_eq!(centre_miss(&case.cameras, &case.observed), None);
        }
    }

    #[test]
    fn a_view_whose_principal_point_is_off_is_the_one_named() {
        for view in 0..3 {
            let mut case = phantom_case(2);
            case.cameras[view].k.cy -= 1024.0;
            match centre_miss(&case.cameras, &case.observed) {
                Some(CentreMiss::View {
                    view: named,
                    miss_mm,
                    others_mm,
                    span_mm,
                }) => {
                    assert_eq!(named, view);
                    assert!(miss_mm > 2.0 * span_mm, "{miss_mm} {span_mm}");
                    assert!(others_mm < 0.1 * span_mm, "{others_mm} {span_mm}");
                }
                other => panic!("view {view}: {other:?}"),
            }
        }
        // Off across the views' common axis instead, the view cannot be told from the others
        // (any two rays meet), and all are refused together.
        let mut case = phantom_case(2);
        case.cameras[1].k.cx -= 1024.0;
        assert!(
            matches!(
                centre_miss(&case.cameras, &case.observed),
                Some(CentreMiss::Views { .. })
            ),
            "{:?}",
            centre_miss(&case.cameras, &case.observed)
        );
        // The companion: a principal point 20 px off (about 3 mm at the object, a pose error
        // the pose refinement can take) is not refused here.
        let mut case = phantom_case(2);
        case.cameras[1].k.cy -= 20.0;
        assert_eq!(centre_miss(&case.cameras, &case.observed), None);
    }

    #[test]
    fn two_views_that_point_apart_are_refused_together() {
        let mut case = phantom_case(2);
        case.cameras.truncate(2);
        case.observed.truncate(2);
        case.cameras[1].k.cy += 1024.0;
        assert!(
            matches!(
                centre_miss(&case.cameras, &case.observed),
                Some(CentreMiss::Views { miss_mm, span_mm }) if miss_mm > MAX_CENTRE_MISS * span_mm
            ),
            "{:?}",
            centre_miss(&case.cameras, &case.observed)
        );
        // The companion: the same two views as simulated agree.
        let case = phantom_case(2);
        let (cams, observed) = (&case.cameras[..2], &case.observed[..2]);
        assert_eq!(centre_miss(cams, observed), None);
    }
}
