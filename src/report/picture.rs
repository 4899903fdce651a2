//! What a picture of the surface asks of a renderer: one square panel of the mesh, coloured per
//! vertex, seen along a direction (`Kernels::render_surface` draws it, on the GPU or its CPU
//! twin; `plots::surface_views` lays two panels out with a colour bar).

use nalgebra::{Point3, Vector3};

/// One panel to draw.
#[derive(Clone, Debug)]
pub struct SurfacePanel<'a> {
    /// Vertices (x, y, z, unused), mm.
    pub points: &'a [[f32; 4]],
    /// Per vertex (r, g, b, unused), 0..1.
    pub colors: &'a [[f32; 4]],
    /// Triangle corner ids, 3 per triangle.
    pub triangles: &'a [u32],
    /// The point at the panel's centre, mm.
    pub center: Point3<f64>,
    /// The viewing direction (away from the viewer).
    pub look: Vector3<f64>,
    /// Roughly up in the panel.
    pub up_hint: Vector3<f64>,
    /// Pixels per mm.
    pub px_per_mm: f64,
    /// Depths range over +- this about the centre, mm.
    pub extent_mm: f64,
    /// The panel's width and height, pixels.
    pub size: u32,
}

/// A panel's pixels: RGBA, row-major from the top-left, white where there is no surface.
pub type PanelPixels = Vec<[u8; 4]>;
