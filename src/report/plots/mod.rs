//! Pictures: the study's error box plots and per-view contour overlays, drawn with plotters into
//! an RGB buffer and saved as PNG with `image`. Text uses DejaVu Sans, shipped inside the program
//! (the `dejavu` crate), so no system font is needed; ACETAB_FONT names another TrueType file.

use crate::io::write_atomic;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

mod overlay;
pub use overlay::{overlay, OverlayMarks};

/// A picture could not be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlotError {
    /// The font could not be loaded (which one, and why).
    #[error("font: {0}")]
    NoFont(String),
    /// plotters or the PNG encoder failed (their message).
    #[error("drawing failed: {0}")]
    Draw(String),
    /// The picture could not be written.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

fn ensure_font() -> Result<(), PlotError> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        let (bytes, what): (&'static [u8], String) = match std::env::var("ACETAB_FONT") {
            Ok(p) => match std::fs::read(&p) {
                // The font lives for the whole program: plotters keeps a 'static reference.
                Ok(b) => (Box::leak(b.into_boxed_slice()), format!("ACETAB_FONT={p}")),
                Err(e) => return Err(format!("ACETAB_FONT={p}: {e}")),
            },
            Err(_) => (dejavu::sans::regular(), "the shipped DejaVu Sans".into()),
        };
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{what} is not a TrueType font plotters can read"))
    })
    .clone()
    .map_err(PlotError::NoFont)
}

fn save_png(buf: Vec<u8>, w: u32, h: u32, path: &Path) -> Result<(), PlotError> {
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| PlotError::Draw("buffer size".into()))?;
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|e| PlotError::Draw(e.to_string()))?;
    write_atomic(path, bytes.get_ref()).map_err(|e| PlotError::File {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

fn draw_err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError::Draw(format!("{e:?}"))
}

/// Quartiles and whiskers (1.5 IQR) of a sample.
fn box_stats(v: &[f64]) -> Option<[f64; 5]> {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return None;
    }
    s.sort_by(f64::total_cmp);
    let q = |f: f64| {
        let x = f * (s.len() - 1) as f64;
        let (i, u) = (x.floor() as usize, x - x.floor());
        s[i] * (1.0 - u) + s[(i + 1).min(s.len() - 1)] * u
    };
    let (q1, q2, q3) = (q(0.25), q(0.5), q(0.75));
    let iqr = q3 - q1;
    let lo = s
        .iter()
        .copied()
        .find(|x| *x >= q1 - 1.5 * iqr)
        .unwrap_or(q1);
    let hi = s
        .iter()
        .rev()
        .copied()
        .find(|x| *x <= q3 + 1.5 * iqr)
        .unwrap_or(q3);
    Some([lo, q1, q2, q3, hi])
}

/// One box-plot panel per metric: x = noise level, one box per group (method), log-free linear
/// y axis. `series[g][l]` holds the values of group g at level `levels[l]`.
pub fn box_plots(
    panels: &[(&str, Vec<Vec<Vec<f64>>>)],
    levels: &[u32],
    groups: &[&str],
    path: &Path,
) -> Result<(), PlotError> {
    ensure_font()?;
    let (w, h) = (600 * panels.len().max(1) as u32, 480u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let areas = root.split_evenly((1, panels.len().max(1)));
        let colors = SERIES_COLORS;
        for ((title, series), area) in panels.iter().zip(areas.iter()) {
            let (ymin, ymax) = box_panel_range(series, groups.len());
            let mut chart = ChartBuilder::on(area)
                .caption(*title, ("sans-serif", 20))
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(56)
                .build_cartesian_2d(0.0..levels.len() as f64, ymin..ymax)
                .map_err(draw_err)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(2 * levels.len() + 1)
                .x_label_formatter(&|x| {
                    let i = x.floor() as usize;
                    if (x - i as f64 - 0.5).abs() < 0.01 {
                        levels
                            .get(i)
                            .map(|l| format!("level {l}"))
                            .unwrap_or_default()
                    } else {
                        String::new()
                    }
                })
                .label_style(("sans-serif", 14))
                .draw()
                .map_err(draw_err)?;
            let ng = groups.len().max(1) as f64;
            for (g, per_level) in series.iter().enumerate() {
                let c = colors[g % colors.len()];
                for (l, vals) in per_level.iter().enumerate() {
                    let Some([lo, q1, q2, q3, hi]) = box_stats(vals) else {
                        continue;
                    };
                    let x0 = l as f64 + 0.1 + 0.8 * g as f64 / ng;
                    let x1 = x0 + 0.8 / ng * 0.8;
                    let outliers = vals
                        .iter()
                        .filter(|v| v.is_finite() && (**v < lo || **v > hi));
                    draw_box(
                        &mut chart,
                        (x0, x1),
                        [lo, q1, q2, q3, hi],
                        outliers,
                        c,
                        (ymin, ymax),
                    )?;
                }
                chart
                    .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                    .map_err(draw_err)?
                    .label(groups[g])
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 12, y + 5)], c.filled())
                    });
            }
            draw_legend(&mut chart)?;
        }
        root.present().map_err(draw_err)?;
    }
    save_png(buf, w, h, path)
}

/// A box plot panel's y range: the whiskers of every box in `series` (not far outliers, which
/// are drawn at the edge), padded, with headroom for the legend of `groups` methods (upper
/// left, about 18 px per method in a plot about 390 px high), so that it never covers a box.
fn box_panel_range(series: &[Vec<Vec<f64>>], groups: usize) -> (f64, f64) {
    let whiskers: Vec<[f64; 5]> = series
        .iter()
        .flatten()
        .filter_map(|v| box_stats(v))
        .collect();
    let hi = whiskers.iter().map(|b| b[4]).fold(0.0f64, f64::max);
    let lo = whiskers.iter().map(|b| b[0]).fold(0.0f64, f64::min);
    let pad = 0.08 * (hi - lo).max(1e-3);
    let (ymin, ymax) = (lo - if lo < 0.0 { pad } else { 0.0 }, hi + pad);
    let legend = ((groups as f64 * 18.0 + 24.0) / 390.0).min(0.6);
    (ymin, ymin + (ymax - ymin) / (1.0 - legend))
}

/// A box plot chart.
type BoxChart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// One box from `x0` to `x1` in colour `c`: the quartiles' box, the median, the whiskers
/// (`[lo, q1, q2, q3, hi]`) and the `outliers` as dots, clamped into the chart's `ymin..ymax`.
fn draw_box<'v>(
    chart: &mut BoxChart,
    (x0, x1): (f64, f64),
    [lo, q1, q2, q3, hi]: [f64; 5],
    outliers: impl Iterator<Item = &'v f64>,
    c: RGBColor,
    (ymin, ymax): (f64, f64),
) -> Result<(), PlotError> {
    let xm = 0.5 * (x0 + x1);
    chart
        .draw_series([Rectangle::new([(x0, q1), (x1, q3)], c.mix(0.35).filled())])
        .map_err(draw_err)?;
    chart
        .draw_series([Rectangle::new([(x0, q1), (x1, q3)], c.stroke_width(1))])
        .map_err(draw_err)?;
    // The median, then the two whiskers.
    chart
        .draw_series([
            PathElement::new(vec![(x0, q2), (x1, q2)], c.stroke_width(2)),
            PathElement::new(vec![(xm, lo), (xm, q1)], c.stroke_width(1)),
            PathElement::new(vec![(xm, q3), (xm, hi)], c.stroke_width(1)),
        ])
        .map_err(draw_err)?;
    let outliers = outliers.map(|v| Circle::new((xm, v.clamp(ymin, ymax)), 3, c.filled()));
    chart.draw_series(outliers).map_err(draw_err)?;
    Ok(())
}

/// One colour per series (method), in order.
const SERIES_COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(140, 86, 75),
];

/// The legend in the upper left, on a white panel.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<(), PlotError> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(draw_err)
}

/// One dot per mesh and series (method): `series[k] = (name, value per mesh)`, meshes along x in
/// the order given, labelled every few meshes.
pub fn per_mesh(
    meshes: &[String],
    series: &[(String, Vec<f64>)],
    y_label: &str,
    path: &Path,
) -> Result<(), PlotError> {
    ensure_font()?;
    let (w, h) = ((300 + 22 * meshes.len() as u32).max(600), 480u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let colors = SERIES_COLORS;
        let hi = series
            .iter()
            .flat_map(|(_, v)| v.iter().copied())
            .filter(|x| x.is_finite())
            .fold(0.0f64, f64::max)
            .max(1e-3);
        let n = meshes.len().max(1);
        let mut chart = ChartBuilder::on(&root)
            .caption(y_label, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(90)
            .y_label_area_size(56)
            .build_cartesian_2d(0.0..n as f64, 0.0..hi * 1.15)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n)
            .x_label_formatter(&|x| {
                let i = x.floor() as usize;
                if (x - i as f64).abs() < 1e-6 {
                    meshes.get(i).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .x_label_style(
                ("sans-serif", 11)
                    .into_font()
                    .transform(FontTransform::Rotate90),
            )
            .label_style(("sans-serif", 13))
            .draw()
            .map_err(draw_err)?;
        for (k, (name, v)) in series.iter().enumerate() {
            let c = colors[k % colors.len()];
            chart
                .draw_series(
                    v.iter()
                        .enumerate()
                        .filter(|(_, y)| y.is_finite())
                        .map(|(i, &y)| Circle::new((i as f64 + 0.5, y), 4, c.filled())),
                )
                .map_err(draw_err)?
                .label(name.as_str())
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, c.filled()));
        }
        draw_legend(&mut chart)?;
        root.present().map_err(draw_err)?;
    }
    save_png(buf, w, h, path)
}

/// The opening axis of a cup-shaped surface on its sphere (`geom::opening_axis`);
/// `surface_views` looks along it.
pub fn opening_axis(
    mesh: &crate::geom::Mesh,
    sphere: &crate::geom::Sphere,
) -> nalgebra::Unit<nalgebra::Vector3<f64>> {
    crate::geom::opening_axis(&mesh.vertices, &sphere.center_point())
}

/// The result from two viewpoints, into the cup (against `axis`) and from the side, coloured
/// by `values` (0 to `max_mm`, grey where NaN) with a colour bar labelled `label`; each panel
/// drawn by `render` (`Kernels::render_surface`: the GPU, or its CPU twin).
#[allow(clippy::too_many_arguments)]
pub fn surface_views(
    mesh: &crate::geom::Mesh,
    values: &[f64],
    axis: &nalgebra::Unit<nalgebra::Vector3<f64>>,
    max_mm: f64,
    label: &str,
    path: &Path,
    render: &dyn Fn(&crate::report::SurfacePanel) -> crate::report::PanelPixels,
) -> Result<(), PlotError> {
    ensure_font()?;
    if mesh.triangles.is_empty() || values.len() != mesh.vertex_count() {
        return Err(PlotError::Draw(
            "no triangles, or not one value per vertex".into(),
        ));
    }
    let (panel, bar_w, h) = (420u32, 150u32, 460u32);
    let w = 2 * panel + bar_w;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let views = surface_looks(axis);
    render_panels(
        mesh,
        values,
        max_mm,
        &views,
        render,
        &mut buf,
        (panel, w, h),
    )?;
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        for (k, (_, title)) in views.iter().enumerate() {
            root.draw(&Text::new(
                *title,
                ((k as u32 * panel + 12) as i32, 4),
                ("sans-serif", 16).into_font().color(&BLACK),
            ))
            .map_err(draw_err)?;
        }
        draw_colour_bar(&root, (2 * panel + 20) as i32, h, max_mm, label)?;
        root.present().map_err(draw_err)?;
    }
    save_png(buf, w, h, path)
}

/// The surface picture's two looks, each with its title: into the cup (against the opening
/// `axis`) and from the side (along the axis turned about z).
fn surface_looks(
    axis: &nalgebra::Unit<nalgebra::Vector3<f64>>,
) -> [(nalgebra::Vector3<f64>, &'static str); 2] {
    use nalgebra::Vector3;
    let a = axis.into_inner();
    let side = Vector3::z()
        .cross(&a)
        .try_normalize(1e-9)
        .unwrap_or(Vector3::x());
    [(-a, "into the cup"), (side, "from the side")]
}

/// The `mesh` coloured by `values` (up to `max_mm`) rendered by `render` along each of `views`
/// into its panel of `buf` (`panel` px square panels side by side, 20 px down under their
/// titles, in a picture `w` x `h`).
fn render_panels(
    mesh: &crate::geom::Mesh,
    values: &[f64],
    max_mm: f64,
    views: &[(nalgebra::Vector3<f64>, &'static str)],
    render: &dyn Fn(&crate::report::SurfacePanel) -> crate::report::PanelPixels,
    buf: &mut [u8],
    (panel, w, h): (u32, u32, u32),
) -> Result<(), PlotError> {
    use nalgebra::Vector3;
    let c = crate::geom::centroid(&mesh.vertices);
    let a = views[0].0;
    let up_hint = if a.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let points: Vec<[f32; 4]> = mesh
        .vertices
        .iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
        .collect();
    let colors: Vec<[f32; 4]> = super::error_colors(values, max_mm)
        .iter()
        .map(|c| {
            [
                c[0] as f32 / 255.0,
                c[1] as f32 / 255.0,
                c[2] as f32 / 255.0,
                1.0,
            ]
        })
        .collect();
    let triangles: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let extent = mesh
        .vertices
        .iter()
        .map(|p| (p - c).norm())
        .fold(1e-9, f64::max);
    let top = 20u32;
    let side_px = panel.min(h - top);
    for (k, (look, _)) in views.iter().enumerate() {
        let px = render(&crate::report::SurfacePanel {
            points: &points,
            colors: &colors,
            triangles: &triangles,
            center: c,
            look: *look,
            up_hint,
            px_per_mm: 0.9 * side_px as f64 / (2.0 * extent),
            extent_mm: 1.01 * extent,
            size: side_px,
        });
        if px.len() != (side_px * side_px) as usize {
            return Err(PlotError::Draw(format!(
                "the renderer gave {} pixels for a {side_px} x {side_px} panel",
                px.len()
            )));
        }
        for y in 0..side_px {
            for x in 0..side_px {
                let [r, g, b, _] = px[(y * side_px + x) as usize];
                let at = (((y + top) * w + k as u32 * panel + x) * 3) as usize;
                buf[at..at + 3].copy_from_slice(&[r, g, b]);
            }
        }
    }
    Ok(())
}

/// The colour bar at `bx` of a picture `h` tall: 0 at the bottom, `max_mm` at the top, grey for
/// "no value", titled `label`.
fn draw_colour_bar(
    root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    bx: i32,
    h: u32,
    max_mm: f64,
    label: &str,
) -> Result<(), PlotError> {
    let (top, bottom) = (50i32, h as i32 - 90);
    for y in top..=bottom {
        let f = (bottom - y) as f64 / (bottom - top) as f64;
        let [r, g, b] = super::error_colors(&[f * max_mm], max_mm)[0];
        root.draw(&PathElement::new(
            vec![(bx, y), (bx + 20, y)],
            RGBColor(r, g, b).stroke_width(1),
        ))
        .map_err(draw_err)?;
    }
    for (f, text) in [
        (0.0, "0".to_string()),
        (0.5, format!("{:.1}", 0.5 * max_mm)),
        (1.0, format!(">= {max_mm:.1}")),
    ] {
        let y = bottom - (f * (bottom - top) as f64) as i32;
        root.draw(&Text::new(
            text,
            (bx + 26, y - 7),
            ("sans-serif", 13).into_font().color(&BLACK),
        ))
        .map_err(draw_err)?;
    }
    let [r, g, b] = super::NO_ERROR_COLOR;
    root.draw(&Rectangle::new(
        [(bx, bottom + 20), (bx + 20, bottom + 34)],
        RGBColor(r, g, b).filled(),
    ))
    .map_err(draw_err)?;
    root.draw(&Text::new(
        "none",
        (bx + 26, bottom + 20),
        ("sans-serif", 13).into_font().color(&BLACK),
    ))
    .map_err(draw_err)?;
    root.draw(&Text::new(
        label.to_string(),
        (bx - 4, 28),
        ("sans-serif", 13).into_font().color(&BLACK),
    ))
    .map_err(draw_err)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_views_draws_a_cap_and_refuses_values_that_do_not_fit() {
        let cap = crate::template::spherical_cap(25.0, 800, 80f64.to_radians());
        let sphere = crate::geom::fit_sphere(&cap.vertices).unwrap();
        let axis = opening_axis(&cap, &sphere);
        // The cap is built about the z axis: its opening axis is z (either sign).
        assert!(axis.z.abs() > 0.99, "{axis:?}");
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("s.png");
        let values: Vec<f64> = (0..cap.vertex_count())
            .map(|i| (i % 30) as f64 / 10.0)
            .collect();
        let cpu = |p: &crate::report::SurfacePanel| crate::engine::Kernels::Cpu.render_surface(p).0;
        surface_views(&cap, &values, &axis, 3.0, "error (mm)", &p, &cpu).unwrap();
        let img = image::open(&p).unwrap().to_rgb8();
        // Something was drawn in each panel (not only the white canvas).
        for x0 in [0u32, 420] {
            let coloured = (x0..x0 + 420)
                .flat_map(|x| (0..460).map(move |y| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y).0 != [255, 255, 255])
                .count();
            assert!(coloured > 10_000, "panel at {x0}: {coloured}");
        }
        // Companion: one value short is refused, not drawn.
        assert!(surface_views(&cap, &values[1..], &axis, 3.0, "x", &p, &cpu).is_err());
    }
}
