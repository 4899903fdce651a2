//! The case's views checked against one another once they are read, each failure named by its
//! field for the case file's error: one acetabulum spans about as much in every view
//! (`outline_span_mismatch`) and lies where every view's outline points
//! (`outline_centre_mismatch`, on `agreement::centre_miss`).

use super::agreement::{centre_miss, CentreMiss};
use crate::geom::{widest_extent, Curve};
use crate::views::Camera;
use std::cmp::Ordering;

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

/// One acetabulum is seen in every view, so its closed outlines span about as much at the object
/// in each: a view's widest closed outline may span from half to twice the median of the other
/// views' (in mm at the template's centre). The outlines simulated from the 78 acetabula of
/// docs/population.md (levels 1 and 5, five draws each) span at least 0.75 of the widest view's
/// with the default views (0 and +-20 degrees about z), 0.71 with inlet and outlet views (x
/// +-30), and 0.56 with views 45-60 degrees apart: a bound for outlines at a wrong scale (a
/// tiny one, one in millimetres instead of pixels) and a view's k off by a factor, not for
/// small disagreements (the outline guard is for those).
pub const MAX_OUTLINE_SPAN_RATIO: f64 = 2.0;

/// The view whose outline spans least like the others' (`MAX_OUTLINE_SPAN_RATIO`), as an error
/// naming it, if any. Each view is measured by its widest closed outline; a view with open ones
/// only, by its widest arc, which is a lower bound of the rim's span: it counts among the others,
/// and is itself refused only for spanning too much.
pub(super) fn outline_span_mismatch(case: &Views) -> Option<Disagreement> {
    /// A view's widest outline: where it is, its span in px and in mm at the object.
    struct Span {
        view: usize,
        contour: usize,
        px: f64,
        mm: f64,
        closed: bool,
    }
    // Each view's widest outline, closed ones first.
    let spans: Vec<Span> = case
        .observed
        .iter()
        .zip(case.px_per_mm)
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
    let (k, (_, median)) = (0..spans.len())
        .filter_map(|k| off(k).map(|o| (k, o)))
        .reduce(|best, x| if x.1 .0 > best.1 .0 { x } else { best })?;
    let Span {
        view,
        contour,
        px,
        mm,
        ..
    } = spans[k];
    Some(disagreement(
        format!("views[{view}].contours[{contour}].points"),
        format!(
            "an outline of view {} spanning {mm:.1} mm at the object ({px:.0} px), against \
             {median:.1} mm in the other views",
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
