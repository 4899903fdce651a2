//! A parametric hemisphere mesh (the method's template M) and its placement in the world.

use crate::geom::Mesh;
use nalgebra::{Point3, Rotation3, Unit, Vector3};

/// Where the template sits: centre of the sphere, radius and the opening axis (from the centre out
/// through the rim plane, i.e. away from the dome).
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    /// Centre of the sphere, mm.
    pub center: Point3<f64>,
    /// Radius, mm.
    pub radius: f64,
    /// Opening axis (unit), from the centre out through the rim plane.
    pub axis: Unit<Vector3<f64>>,
}

impl Placement {
    /// Rotation taking the template's local +z (opening axis) onto `axis` (shortest arc; about
    /// the local x axis when the axis points straight down).
    pub fn rotation(&self) -> Rotation3<f64> {
        Rotation3::rotation_between(&Vector3::z(), &self.axis)
            .unwrap_or_else(|| Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI))
    }

    /// The unit-radius template placed here.
    pub fn place(&self, unit_template: &Mesh) -> Mesh {
        unit_template.transformed(self.radius, &self.rotation(), &self.center.coords)
    }
}

/// Most vertices `spherical_cap` builds (about; larger targets are taken as this).
pub const MAX_CAP_VERTICES: usize = 1_000_000;

/// Unit-sphere cap mesh in its local frame: points R(sin t cos p, sin t sin p, -cos t) for polar
/// angle t in [0, max_polar], dome at -z, opening towards +z, faces oriented with normals pointing
/// away from the centre. `target_vertices` sets the resolution (rings are spaced evenly in t and
/// each ring gets as many points as its circumference allows, up to `MAX_CAP_VERTICES`).
/// `max_polar` is taken within [1 degree, 179 degrees] (a NaN as 90 degrees): outside it there
/// is no cap to build, and `ReconParams::validate` refuses such a template.
pub fn spherical_cap(radius: f64, target_vertices: usize, max_polar: f64) -> Mesh {
    let max_polar = if max_polar.is_nan() {
        std::f64::consts::FRAC_PI_2
    } else {
        max_polar.clamp(1f64.to_radians(), 179f64.to_radians())
    };
    let target_vertices = target_vertices.min(MAX_CAP_VERTICES);
    let area_ratio = 1.0 - max_polar.cos(); // cap area / (2 pi R^2)
                                            // Vertex spacing h so that area / (h^2 sqrt(3)/2) ~ target.
    let h =
        (2.0 * std::f64::consts::PI * area_ratio / (target_vertices.max(16) as f64 * 0.866)).sqrt();
    let rings = ((max_polar / h).round() as usize).max(2);
    let mut vertices = vec![Point3::new(0.0, 0.0, -radius)];
    let mut ring_start = vec![0usize];
    let mut ring_len = vec![1usize];
    for k in 1..=rings {
        let t = max_polar * k as f64 / rings as f64;
        let n = ((2.0 * std::f64::consts::PI * t.sin() / h).round() as usize).max(6);
        ring_start.push(vertices.len());
        ring_len.push(n);
        let offset = if k % 2 == 0 { 0.5 } else { 0.0 };
        for j in 0..n {
            let p = 2.0 * std::f64::consts::PI * (j as f64 + offset) / n as f64;
            vertices.push(Point3::new(
                radius * t.sin() * p.cos(),
                radius * t.sin() * p.sin(),
                -radius * t.cos(),
            ));
        }
    }
    let mut triangles = Vec::new();
    for k in 0..rings {
        zip_rings(
            &vertices,
            ring_start[k],
            ring_len[k],
            ring_start[k + 1],
            ring_len[k + 1],
            &mut triangles,
        );
    }
    let mut mesh = Mesh {
        vertices,
        triangles,
        normals: Vec::new(),
    };
    orient_outward(&mut mesh);
    mesh.recompute_normals();
    mesh
}

/// The template hemisphere (max polar angle 90 degrees).
pub fn hemisphere(radius: f64, target_vertices: usize) -> Mesh {
    spherical_cap(radius, target_vertices, std::f64::consts::FRAC_PI_2)
}

fn azimuth(p: &Point3<f64>) -> f64 {
    p.y.atan2(p.x).rem_euclid(2.0 * std::f64::consts::PI)
}

/// Triangulate the band between an inner ring and an outer ring by merging them in azimuth order.
/// Each ring's points are stored in increasing azimuth starting just after 0.
fn zip_rings(
    v: &[Point3<f64>],
    a0: usize,
    na: usize,
    b0: usize,
    nb: usize,
    out: &mut Vec<[u32; 3]>,
) {
    if na == 1 {
        for j in 0..nb {
            out.push([a0 as u32, (b0 + j) as u32, (b0 + (j + 1) % nb) as u32]);
        }
        return;
    }
    let turn = 2.0 * std::f64::consts::PI;
    let angle =
        |start: usize, n: usize, i: usize| azimuth(&v[start + i % n]) + turn * (i / n) as f64;
    let ai = |i: usize| (a0 + i % na) as u32;
    let bj = |j: usize| (b0 + j % nb) as u32;
    let (mut i, mut j) = (0usize, 0usize);
    while i < na || j < nb {
        let advance_inner = j >= nb || (i < na && angle(a0, na, i + 1) <= angle(b0, nb, j + 1));
        if advance_inner {
            out.push([ai(i), ai(i + 1), bj(j)]);
            i += 1;
        } else {
            out.push([ai(i), bj(j + 1), bj(j)]);
            j += 1;
        }
    }
}

/// Flip any triangle whose normal points towards the sphere centre (the origin).
fn orient_outward(mesh: &mut Mesh) {
    for t in &mut mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let n = (b - a).cross(&(c - a));
        let centroid = (a.coords + b.coords + c.coords) / 3.0;
        if n.dot(&centroid) < 0.0 {
            t.swap(1, 2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hemisphere_is_a_watertight_cap_with_outward_normals() {
        let m = hemisphere(26.0, 2500);
        assert!(
            (2000..3100).contains(&m.vertex_count()),
            "{}",
            m.vertex_count()
        );
        let exact = 2.0 * std::f64::consts::PI * 26.0 * 26.0;
        assert!(
            (m.area() - exact).abs() / exact < 0.01,
            "area {} vs {exact}",
            m.area()
        );
        for (p, n) in m.vertices.iter().zip(&m.normals) {
            assert!((p.coords.norm() - 26.0).abs() < 1e-9);
            assert!(p.z <= 1e-9);
            assert!(n.dot(&p.coords.normalize()) > 0.9);
        }
        // Only the rim is open: boundary edges lie at z = 0.
        let b = m.boundary_edges();
        assert!(!b.is_empty());
        for [i, j] in b {
            assert!(m.vertices[i as usize].z.abs() < 1e-9 && m.vertices[j as usize].z.abs() < 1e-9);
        }
    }

    #[test]
    fn a_cap_outside_its_range_is_built_at_the_nearest_one_not_endlessly() {
        // 360 degrees used to ask for infinitely many rings.
        let full = spherical_cap(1.0, 500, 2.0 * std::f64::consts::PI);
        let edge = spherical_cap(1.0, 500, 179f64.to_radians());
        assert_eq!(full.vertices, edge.vertices);
        let nan = spherical_cap(1.0, 500, f64::NAN);
        assert_eq!(nan.vertices, hemisphere(1.0, 500).vertices);
        let tiny = spherical_cap(1.0, 500, -1.0);
        assert!(tiny.vertex_count() > 3 && tiny.vertices.iter().all(|p| p.z < 0.0));
        // Companion: within the range the extent is the one asked for.
        let deep = spherical_cap(1.0, 500, 120f64.to_radians());
        assert_ne!(deep.vertices, edge.vertices);
        let top = deep.vertices.iter().map(|p| p.z).fold(f64::MIN, f64::max);
        assert!((top - 0.5).abs() < 1e-9, "{top}");
    }

    #[test]
    fn placement_maps_local_z_to_the_axis() {
        let pl = Placement {
            center: Point3::new(1.0, 2.0, 3.0),
            radius: 2.0,
            axis: Unit::new_normalize(Vector3::new(0.0, 0.0, -1.0)),
        };
        let m = pl.place(&hemisphere(1.0, 300));
        for p in &m.vertices {
            assert!(((p - pl.center).norm() - 2.0).abs() < 1e-9);
            assert!((p - pl.center).dot(&pl.axis) <= 1e-9);
        }
    }
}
