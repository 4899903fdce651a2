//! A view's annotated contours as a case file gives them: each contour's points inside the
//! image, its distinct points enough and wide enough, a closed one going once round its rim,
//! without a stray point and enclosing most of its convex hull, and one acetabulum's rim a view.
//! A closed outline that looks like an open arc joined by its chord is a warning.

use super::{field_err, CaseError, ContourFile, ContourKind, ViewFile};
use crate::geom::{
    hull_fill, longest_segment, stray_point, turns_round_centroid, widest_extent, Curve,
};
use crate::pipeline::{
    fills_hull, IMAGE_MARGIN, MAX_OUTLINE_POINTS, MIN_HULL_FILL, MIN_OUTLINE_EXTENT_PX,
    MIN_OUTLINE_POINTS,
};
use nalgebra::Point2;
use std::path::Path;

/// A closed outline's longest step, as a share of its widest extent, at which it looks like an
/// open arc joined by its chord. The closed outlines simulated from the 47 shared acetabula
/// (the default, inlet/outlet and 45-degree views; levels 1 and 5; both protocols; 846
/// outlines) reach 0.47 where one straight step spans the notch; the same outlines cut to their
/// first half of points and left closed pass this and `OPEN_ARC_RATIO` in 610 of 846, cut to
/// 60 % in 464 (tests/case_agreement.rs): a warning for the clear cases, not a proof.
pub const OPEN_ARC_SHARE: f64 = 0.6;
/// ... and as a multiple of its next longest step (points clicked few and evenly, a square of
/// four, have all their steps alike).
pub const OPEN_ARC_RATIO: f64 = 3.0;

/// A closed outline's longest step when it looks like an open arc closed by its chord
/// (`OPEN_ARC_SHARE`, `OPEN_ARC_RATIO`): a warning, not an error, for an outline may bridge
/// a wide notch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpenArc {
    /// The step runs from this point (of the distinct points) to the next.
    pub from: usize,
    /// Its length, px.
    pub px: f64,
    /// Its length over the outline's widest extent.
    pub share: f64,
    /// The next longest step, px.
    pub next_px: f64,
}

/// The closed outline `pts`' longest step where it looks like an open arc's chord (`OpenArc`),
/// else None: the check a case file's closed contours get.
pub fn open_arc(pts: &[Point2<f64>]) -> Option<OpenArc> {
    let (from, px, next_px) = longest_segment(pts)?;
    let share = px / widest_extent(pts);
    (share >= OPEN_ARC_SHARE && px >= OPEN_ARC_RATIO * next_px).then_some(OpenArc {
        from,
        px,
        share,
        next_px,
    })
}

/// A view's outlines as the method takes them.
pub(super) struct ViewContours {
    /// Its curves: one closed outline, or open arcs.
    pub curves: Vec<Curve>,
    /// The points of its contours marked `clicked`, as given.
    pub clicks: Vec<Point2<f64>>,
    /// Closed outlines that look like open arcs (`open_arc`).
    pub warnings: Vec<String>,
}

/// The contours of view `vi` (`v`, its image `width` x `height`) of the case file at `path`.
pub(super) fn view_contours(
    path: &Path,
    vi: usize,
    v: &ViewFile,
    (width, height): (u32, u32),
) -> Result<ViewContours, CaseError> {
    if v.contours.is_empty() {
        return Err(field_err(
            path,
            format!("views[{vi}].contours"),
            "[]",
            "each view needs at least one contour",
        ));
    }
    let mut out = ViewContours {
        curves: Vec::new(),
        clicks: Vec::new(),
        warnings: Vec::new(),
    };
    for (ci, c) in v.contours.iter().enumerate() {
        let curve = contour(path, (vi, ci), c, (width, height), &mut out.warnings)?;
        out.curves.push(match c.clicked {
            Some(true) => {
                out.clicks.extend_from_slice(&curve.points);
                curve.clicked()
            }
            _ => curve,
        });
    }
    // One acetabulum's rim a view: one closed outline, or open arcs of it. A second closed
    // outline (the femoral head, the other hip) or a closed one beside arcs would be matched to
    // the same model outline and pull the surface apart.
    let closed_count = out.curves.iter().filter(|c| c.closed).count();
    if closed_count > 1 || (closed_count == 1 && out.curves.len() > 1) {
        return Err(field_err(
            path,
            format!("views[{vi}].contours"),
            format!(
                "{} contours, {closed_count} of them closed",
                out.curves.len()
            ),
            "a view holds one acetabulum's rim: one closed contour, or one or more \
             open arcs of it; is one of them another outline (the femoral head, the \
             other hip, the teardrop)?",
        ));
    }
    Ok(out)
}

/// Contour `ci` of view `vi` (`c`) as a curve of its distinct points, as given (before
/// `Curve::clicked`); a closed one that looks like an open arc adds a warning to `warnings`.
fn contour(
    path: &Path,
    at: (usize, usize),
    c: &ContourFile,
    image: (u32, u32),
    warnings: &mut Vec<String>,
) -> Result<Curve, CaseError> {
    points_in_image(path, at, c, image)?;
    let closed = closed_of(path, at, c)?;
    let (pts, index) = distinct_points(c, closed);
    enough_and_once_round(path, at, c, &pts, &index, closed)?;
    if closed {
        encloses_its_hull(path, at, c, &pts)?;
        if let Some(w) = open_arc(&pts) {
            warnings.push(open_arc_warning(path, at, &w, &index));
        }
    }
    Ok(Curve {
        points: pts,
        closed,
    })
}

/// The field name `name` of contour `ci` of view `vi`.
fn field((vi, ci): (usize, usize), name: &str) -> String {
    format!("views[{vi}].contours[{ci}].{name}")
}

/// At most `MAX_OUTLINE_POINTS` points, each finite and inside the `width` x `height` image
/// (give or take `IMAGE_MARGIN`).
fn points_in_image(
    path: &Path,
    at: (usize, usize),
    c: &ContourFile,
    (width, height): (u32, u32),
) -> Result<(), CaseError> {
    if c.points.len() > MAX_OUTLINE_POINTS {
        return Err(field_err(
            path,
            field(at, "points"),
            format!("{} points", c.points.len()),
            format!("a contour has at most {MAX_OUTLINE_POINTS} points (thin it)"),
        ));
    }
    let margin = IMAGE_MARGIN * f64::from(width.max(height));
    for (pi, p) in c.points.iter().enumerate() {
        if !p[0].is_finite() || !p[1].is_finite() {
            return Err(field_err(
                path,
                field(at, &format!("points[{pi}]")),
                format!("{p:?}"),
                "coordinates must be finite",
            ));
        }
        if p[0] < -margin
            || p[1] < -margin
            || p[0] > width as f64 + margin
            || p[1] > height as f64 + margin
        {
            return Err(field_err(
                path,
                field(at, &format!("points[{pi}]")),
                format!("{p:?}"),
                format!("outside the {width}x{height} image"),
            ));
        }
    }
    Ok(())
}

/// Whether the contour is closed, from `closed` or `kind` (which must agree when both are given).
fn closed_of(path: &Path, at: (usize, usize), c: &ContourFile) -> Result<bool, CaseError> {
    match (c.closed, c.kind) {
        (Some(b), None) => Ok(b),
        (None, Some(k)) => Ok(k == ContourKind::Closed),
        (Some(b), Some(k)) if b == (k == ContourKind::Closed) => Ok(b),
        (b, k) => Err(field_err(
            path,
            field(at, "closed/kind"),
            format!("closed {b:?}, kind {k:?}"),
            "give either \"closed\": true|false or \"kind\": \"closed\"|\"open\"|\"partial\" (and not two that disagree)",
        )),
    }
}

/// The contour's distinct points (a point repeating the one before it dropped, and a closed
/// one's explicitly repeated first point), each with its index in the file.
fn distinct_points(c: &ContourFile, closed: bool) -> (Vec<Point2<f64>>, Vec<usize>) {
    let mut pts: Vec<Point2<f64>> = Vec::with_capacity(c.points.len());
    let mut index: Vec<usize> = Vec::with_capacity(c.points.len());
    for (pi, p) in c.points.iter().enumerate() {
        let q = Point2::new(p[0], p[1]);
        if pts.last().is_none_or(|last| (q - last).norm() >= 1e-9) {
            pts.push(q);
            index.push(pi);
        }
    }
    if closed && pts.len() > 1 && (pts[0] - pts[pts.len() - 1]).norm() < 1e-9 {
        pts.pop();
        index.pop();
    }
    (pts, index)
}

/// Enough distinct points `pts` (their indices in the file `index`), spread wide enough, a
/// closed contour going once round its centre, and no stray point.
fn enough_and_once_round(
    path: &Path,
    at: (usize, usize),
    c: &ContourFile,
    pts: &[Point2<f64>],
    index: &[usize],
    closed: bool,
) -> Result<(), CaseError> {
    if pts.len() < MIN_OUTLINE_POINTS {
        return Err(field_err(
            path,
            field(at, "points"),
            format!("{} distinct points", pts.len()),
            format!("a contour needs at least {MIN_OUTLINE_POINTS} distinct points"),
        ));
    }
    let extent = pts.iter().map(|p| (p - pts[0]).norm()).fold(0.0, f64::max);
    if extent < MIN_OUTLINE_EXTENT_PX {
        return Err(field_err(
            path,
            field(at, "points"),
            format!("extent {extent:.3} px"),
            format!("the contour is smaller than {MIN_OUTLINE_EXTENT_PX} pixels"),
        ));
    }
    // A closed outline traced round more than once (two passes of the annotation joined) goes
    // twice round its own centre; a noisy or notched one, once.
    let turns = if closed { turns_round_centroid(pts) } else { 1 };
    if turns > 1 {
        return Err(field_err(
            path,
            field(at, "points"),
            format!(
                "{} points going {turns} times round their centre",
                c.points.len()
            ),
            "a closed contour goes once round the rim: is it traced twice?",
        ));
    }
    if let Some(s) = stray_point(pts, closed) {
        let pi = index[s.index];
        return Err(field_err(
            path,
            field(at, &format!("points[{pi}]")),
            format!("{:?}", c.points[pi]),
            format!(
                "a stray point: {:.0} px from both its neighbours, which lie {:.0} px \
                 apart (the contour's points are {:.0} px apart at the median); \
                 remove or correct it",
                s.off_px, s.neighbours_px, s.spacing_px
            ),
        ));
    }
    Ok(())
}

/// A closed rim encloses most of its convex hull; points on one line enclose nothing, and an
/// outline that crosses itself (parts joined in the wrong order) little, its loops' areas
/// cancelling.
fn encloses_its_hull(
    path: &Path,
    at: (usize, usize),
    c: &ContourFile,
    pts: &[Point2<f64>],
) -> Result<(), CaseError> {
    let (inside, hull) = hull_fill(pts);
    if fills_hull(inside, hull) {
        return Ok(());
    }
    Err(field_err(
        path,
        field(at, "points"),
        format!(
            "{} points enclosing {inside:.0} px^2 of their convex hull's \
             {hull:.0} px^2",
            c.points.len()
        ),
        format!(
            "a closed rim encloses at least {:.0} % of its convex hull: are \
             its points on one line, or does it cross itself (parts of the \
             annotation joined in the wrong order)?",
            100.0 * MIN_HULL_FILL
        ),
    ))
}

/// The warning for a closed outline that looks like an open arc joined by its chord (`w`,
/// from its distinct points, whose indices in the file are `index`).
fn open_arc_warning(path: &Path, at: (usize, usize), w: &OpenArc, index: &[usize]) -> String {
    let (i, j) = (index[w.from], index[(w.from + 1) % index.len()]);
    format!(
        "{}: {}: a closed outline whose points {i} and {j} lie {:.0} px \
         apart, {:.0} % of its width, against {:.0} px for its next longest \
         step: if it is an open arc (the rim left out where the walls are \
         blurred), give it \"closed\": false; closed, that straight segment \
         is taken for rim",
        path.display(),
        field(at, "closed"),
        w.px,
        100.0 * w.share,
        w.next_px
    )
}
