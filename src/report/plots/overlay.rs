//! A view's contours over its X-ray: the initial and final model outlines, the observation, the
//! catalogue cup, the clicked points, a scale bar and a legend.

use super::{draw_err, ensure_font, save_png, PlotError};
use crate::geom::Curve;
use nalgebra::Point2;
use plotters::prelude::*;
use std::path::Path;

const INITIAL: RGBColor = RGBColor(40, 200, 60);
const RESULT: RGBColor = RGBColor(60, 120, 255);
const OBSERVED: RGBColor = RGBColor(230, 40, 40);

const CUP: RGBColor = RGBColor(250, 210, 40);

/// What an overlay shows besides the contours, each optional: the view's name (upper right), a
/// 10 mm scale bar at the object's depth (`px_per_mm`, lower left), the chosen catalogue cup's
/// outline in the view (yellow), labelled with its size, as a templating film shows it, and the
/// points an annotator clicked (dots on the observation, which is the curve through them).
#[derive(Clone, Debug, Default)]
pub struct OverlayMarks {
    /// The view's name.
    pub view: Option<String>,
    /// Pixels per millimetre at the object.
    pub px_per_mm: Option<f64>,
    /// The catalogue cup's outline (`Camera::sphere_outline`) and its size, mm.
    pub cup: Option<(Vec<Point2<f64>>, f64)>,
    /// The clicked points of the view's annotation (`Case::clicks`); none drawn when empty.
    pub clicks: Vec<Point2<f64>>,
}

impl OverlayMarks {
    /// The marks of a result's overlay in view `cam` named `view`: the scale bar at the depth of
    /// the cup's centre `center`, the outline of the chosen catalogue cup (`catalogue_mm`)
    /// there, and the view's `clicks`.
    pub fn of_result(
        view: String,
        cam: &crate::views::Camera,
        center: &nalgebra::Point3<f64>,
        catalogue_mm: f64,
        clicks: &[Point2<f64>],
    ) -> OverlayMarks {
        OverlayMarks {
            view: Some(view),
            px_per_mm: Some(cam.pixels_per_mm_at(center)),
            cup: Some((
                cam.sphere_outline(center, 0.5 * catalogue_mm, 120),
                catalogue_mm,
            )),
            clicks: clicks.to_vec(),
        }
    }
}

/// Radius of a clicked point's dot on an overlay, px.
const CLICK_DOT_PX: i32 = 4;

/// A view's contours over its X-ray (or a dark canvas), cropped around them: initial model
/// contour green, result blue, observation red on top (closed where the curve is), as in the
/// paper's Fig. 3, with a legend in the upper left when a font is found, and `marks`.
pub fn overlay(
    size: (u32, u32),
    background: Option<&Path>,
    initial: &[Point2<f64>],
    result: &[Point2<f64>],
    observed: &[Curve],
    marks: &OverlayMarks,
    path: &Path,
) -> Result<(), PlotError> {
    let cup_pts: &[Point2<f64>] = marks.cup.as_ref().map_or(&[], |(c, _)| c.as_slice());
    let all: Vec<&Point2<f64>> = initial
        .iter()
        .chain(result)
        .chain(observed.iter().flat_map(|c| c.points.iter()))
        .chain(cup_pts)
        .chain(&marks.clicks)
        .collect();
    let crop = Crop::around(&all, size)?;
    let mut buf = crop.background(background)?;
    {
        let root = BitMapBackend::with_buffer(&mut buf, (crop.w, crop.h)).into_drawing_area();
        root.draw(&PathElement::new(
            crop.to_px(initial, true),
            INITIAL.stroke_width(2),
        ))
        .map_err(draw_err)?;
        if !cup_pts.is_empty() {
            root.draw(&PathElement::new(
                crop.to_px(cup_pts, true),
                CUP.stroke_width(1),
            ))
            .map_err(draw_err)?;
        }
        root.draw(&PathElement::new(
            crop.to_px(result, true),
            RESULT.stroke_width(2),
        ))
        .map_err(draw_err)?;
        // The observation on top: where the annotation leaves a gap, the result shows through.
        for c in observed {
            root.draw(&PathElement::new(
                crop.to_px(&c.points, c.closed),
                OBSERVED.stroke_width(2),
            ))
            .map_err(draw_err)?;
        }
        for p in &marks.clicks {
            root.draw(&Circle::new(crop.at(p), CLICK_DOT_PX, OBSERVED.filled()))
                .map_err(draw_err)?;
        }
        if ensure_font().is_ok() {
            draw_scale_and_name(&root, marks, (crop.w, crop.h))?;
            if crop.w >= 140 && crop.h >= 70 {
                draw_overlay_legend(&root, marks)?;
            }
        }
        root.present().map_err(draw_err)?;
    }
    save_png(buf, crop.w, crop.h, path)
}

/// An overlay's window on its X-ray: from (`x0`, `y0`), `w` x `h` pixels.
struct Crop {
    x0: f64,
    y0: f64,
    w: u32,
    h: u32,
}

impl Crop {
    /// Round the points `all`, with a margin and room above for the legend, inside the image of
    /// `size`; an error when there is nothing to draw.
    fn around(all: &[&Point2<f64>], size: (u32, u32)) -> Result<Crop, PlotError> {
        if all.is_empty() {
            return Err(PlotError::Draw("no contours to draw".into()));
        }
        let margin = 40.0;
        let x0 = (all.iter().map(|p| p.x).fold(f64::INFINITY, f64::min) - margin)
            .max(0.0)
            .floor();
        // Room above the contours for the legend.
        let y0 = (all.iter().map(|p| p.y).fold(f64::INFINITY, f64::min) - margin - 90.0)
            .max(0.0)
            .floor();
        let x1 = (all.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max) + margin)
            .min(size.0 as f64)
            .ceil();
        let y1 = (all.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max) + margin)
            .min(size.1 as f64)
            .ceil();
        let (w, h) = (((x1 - x0).max(16.0)) as u32, ((y1 - y0).max(16.0)) as u32);
        Ok(Crop { x0, y0, w, h })
    }

    /// The window's RGB pixels: the X-ray at `background` where it reaches, else dark.
    fn background(&self, background: Option<&Path>) -> Result<Vec<u8>, PlotError> {
        let (w, h) = (self.w, self.h);
        let Some(p) = background else {
            return Ok(vec![24u8; (w * h * 3) as usize]);
        };
        let img = crate::io::read_xray_image(p)
            .map_err(|reason| PlotError::File {
                path: p.to_path_buf(),
                reason,
            })?
            .to_rgb8();
        let mut b = vec![0u8; (w * h * 3) as usize];
        for y in 0..h {
            for x in 0..w {
                let (sx, sy) = (self.x0 as u32 + x, self.y0 as u32 + y);
                if sx < img.width() && sy < img.height() {
                    let px = img.get_pixel(sx, sy).0;
                    b[((y * w + x) * 3) as usize..][..3].copy_from_slice(&px);
                }
            }
        }
        Ok(b)
    }

    /// Point `p` in the window's pixels.
    fn at(&self, p: &Point2<f64>) -> (i32, i32) {
        (
            (p.x - self.x0).round() as i32,
            (p.y - self.y0).round() as i32,
        )
    }

    /// The curve `c` in the window's pixels, its first point repeated at the end when `close`.
    fn to_px(&self, c: &[Point2<f64>], close: bool) -> Vec<(i32, i32)> {
        let mut v: Vec<(i32, i32)> = c.iter().map(|p| self.at(p)).collect();
        if close && !v.is_empty() {
            v.push(v[0]);
        }
        v
    }
}

/// An overlay's drawing area.
type Canvas<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// The 10 mm scale bar at the object (lower left, when the window is tall enough) and the
/// view's name (upper right) of `marks`, on a window `w` x `h`.
fn draw_scale_and_name(
    root: &Canvas,
    marks: &OverlayMarks,
    (w, h): (u32, u32),
) -> Result<(), PlotError> {
    if let (Some(ppm), true) = (marks.px_per_mm, h >= 60) {
        let len = (10.0 * ppm).round() as i32;
        let (x, y) = (12, h as i32 - 16);
        root.draw(&PathElement::new(
            vec![(x, y), (x + len, y)],
            WHITE.stroke_width(3),
        ))
        .map_err(draw_err)?;
        root.draw(&Text::new(
            "10 mm",
            (x + len + 6, y - 8),
            ("sans-serif", 14).into_font().color(&WHITE),
        ))
        .map_err(draw_err)?;
    }
    if let Some(name) = &marks.view {
        let x = (w as i32 - 8 - 8 * name.chars().count() as i32).max(120);
        root.draw(&Text::new(
            name.as_str(),
            (x, 8),
            ("sans-serif", 16).into_font().color(&WHITE),
        ))
        .map_err(draw_err)?;
    }
    Ok(())
}

/// The legend in the upper left: initial, result, observed, the cup when `marks` has one, and
/// the clicked points' dot when it has clicks.
fn draw_overlay_legend(root: &Canvas, marks: &OverlayMarks) -> Result<(), PlotError> {
    let cup_label = marks.cup.as_ref().map(|(_, mm)| format!("cup {mm:.0} mm"));
    let mut entries = vec![
        ("initial", INITIAL),
        ("result", RESULT),
        ("observed", OBSERVED),
    ];
    if let Some(l) = &cup_label {
        entries.push((l.as_str(), CUP));
    }
    let clicked = !marks.clicks.is_empty();
    root.draw(&Rectangle::new(
        [
            (4, 4),
            (124, 10 + 18 * (entries.len() + usize::from(clicked)) as i32),
        ],
        RGBColor(0, 0, 0).mix(0.6).filled(),
    ))
    .map_err(draw_err)?;
    if clicked {
        let y = 16 + 18 * entries.len() as i32;
        root.draw(&Circle::new((22, y), CLICK_DOT_PX, OBSERVED.filled()))
            .map_err(draw_err)?;
        root.draw(&Text::new(
            "clicked",
            (40, y - 7),
            ("sans-serif", 14).into_font().color(&WHITE),
        ))
        .map_err(draw_err)?;
    }
    for (i, (label, colour)) in entries.into_iter().enumerate() {
        let y = 16 + 18 * i as i32;
        root.draw(&PathElement::new(
            vec![(10, y), (34, y)],
            colour.stroke_width(3),
        ))
        .map_err(draw_err)?;
        root.draw(&Text::new(
            label,
            (40, y - 7),
            ("sans-serif", 14).into_font().color(&WHITE),
        ))
        .map_err(draw_err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The clicked points are dots on the observation: a pixel 3 px off the observed curve at a
    /// click is the observation's red with the click given, and the dark canvas without.
    #[test]
    fn an_overlay_marks_the_clicked_points() {
        let ring = |r: f64, n: usize| -> Vec<Point2<f64>> {
            (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    Point2::new(300.0 + r * a.cos(), 300.0 + r * a.sin())
                })
                .collect()
        };
        let observed = [Curve {
            points: ring(100.0, 200),
            closed: true,
        }];
        let click = Point2::new(400.0, 300.0);
        let tmp = tempfile::tempdir().unwrap();
        let draw = |clicks: Vec<Point2<f64>>, name: &str| {
            let marks = OverlayMarks {
                clicks,
                ..Default::default()
            };
            let p = tmp.path().join(name);
            overlay(
                (600, 600),
                None,
                &ring(60.0, 50),
                &ring(80.0, 50),
                &observed,
                &marks,
                &p,
            )
            .unwrap();
            image::open(&p).unwrap().to_rgb8()
        };
        let with = draw(vec![click, Point2::new(200.0, 300.0)], "with.png");
        let without = draw(Vec::new(), "without.png");
        // The crop starts 40 px left of the leftmost point and 130 px above the topmost.
        let (x, y) = ((click.x + 3.0 - 160.0) as u32, (click.y - 70.0) as u32);
        let red = |c: [u8; 3]| c[0] > 150 && c[1] < 100 && c[2] < 100;
        assert!(red(with.get_pixel(x, y).0), "{:?}", with.get_pixel(x, y));
        assert!(
            !red(without.get_pixel(x, y).0),
            "{:?}",
            without.get_pixel(x, y)
        );
    }
}
