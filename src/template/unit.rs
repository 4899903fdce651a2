//! The template M as the reconstruction takes it: a mesh in its local frame (unit sphere about
//! the origin, dome towards -z, opening towards +z), with its rim marked. The standard one is the
//! hemisphere (`Template::cap`); an embedder may pass its own (`Template::new`), e.g. a mean
//! acetabulum scaled to unit radius.

use super::spherical_cap;
use crate::geom::{fit_sphere_robust, Mesh};

/// Most template vertices a reconstruction takes (the standard template has 2,500).
pub const MAX_TEMPLATE_VERTICES: usize = 200_000;

/// The standard template's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct TemplateParams {
    /// Resolution (default 2,500 vertices).
    pub vertices: usize,
    /// Polar extent of the cap, degrees (default 90: the hemisphere).
    pub polar_deg: f64,
}

impl Default for TemplateParams {
    fn default() -> Self {
        TemplateParams {
            vertices: 2500,
            polar_deg: 90.0,
        }
    }
}

/// Why a mesh cannot be the template.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TemplateError {
    /// A setting of the standard template outside what builds a cap.
    #[error("template setting {field} = {value}: must be {expected}")]
    Setting {
        /// The field of `TemplateParams`.
        field: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
    /// More vertices than a reconstruction takes.
    #[error("the template has {count} vertices; at most {max} are taken")]
    TooLarge {
        /// Vertices of the mesh.
        count: usize,
        /// `MAX_TEMPLATE_VERTICES`.
        max: usize,
    },
    /// Not a mesh: a triangle's corner that is not a vertex, a non-finite coordinate, no area.
    #[error("the template's mesh: {0}")]
    Mesh(#[from] crate::geom::MeshError),
    /// Its triangles wind the other way round: they face the sphere's centre.
    #[error(
        "{:.0} % of the template's area faces its sphere's centre: its triangles must wind \
         counter-clockwise seen from outside (reverse each triangle's corners)",
        100.0 * share
    )]
    Inward {
        /// The share of its area facing inward.
        share: f64,
    },
    /// No border: a closed surface has no rim to meet the outlines.
    #[error("the template has no border (a closed surface has no rim)")]
    NoRim,
    /// Not in the template's local frame.
    #[error(
        "the template's sphere has centre {center:?} and radius {radius}: a template lies on \
         the unit sphere about the origin (centre within 0.25, radius 0.75-1.25)"
    )]
    NotUnit {
        /// Centre of its best-fit sphere.
        center: [f64; 3],
        /// Radius of its best-fit sphere.
        radius: f64,
    },
}

/// The template in its local frame and which of its vertices lie on its rim.
#[derive(Clone, Debug, PartialEq)]
pub struct Template {
    mesh: Mesh,
    on_rim: Vec<bool>,
}

impl Template {
    /// The standard template: the unit spherical cap of `p.polar_deg` degrees with about
    /// `p.vertices` vertices.
    pub fn cap(p: &TemplateParams) -> Result<Template, TemplateError> {
        let polar = p.polar_deg;
        if !(polar > 0.0 && polar < 180.0) {
            return Err(TemplateError::Setting {
                field: "polar_deg",
                value: crate::io::shown(&polar.to_string()),
                expected: "in (0, 180) degrees",
            });
        }
        if p.vertices > MAX_TEMPLATE_VERTICES {
            return Err(TemplateError::Setting {
                field: "vertices",
                value: crate::io::shown(&p.vertices.to_string()),
                expected: "at most 200,000",
            });
        }
        Ok(Template::marked(spherical_cap(
            1.0,
            p.vertices,
            polar.to_radians(),
        )))
    }

    /// The standard template with the default settings (the hemisphere, about 2,500
    /// vertices).
    pub fn standard() -> Template {
        Template::cap(&TemplateParams::default()).expect("the default settings build a cap")
    }

    /// The caller's own template: a mesh on the unit sphere about the origin (its best-fit
    /// sphere's centre within 0.25 of it, radius 0.75-1.25), opening towards +z, with a border.
    /// The mesh is checked as `Mesh::new` checks one (its fields are public), and its normals
    /// are recomputed when there are not one per vertex.
    pub fn new(mut mesh: Mesh) -> Result<Template, TemplateError> {
        mesh.check()?;
        if mesh.normals.len() != mesh.vertices.len() {
            mesh.recompute_normals();
        }
        if mesh.vertex_count() > MAX_TEMPLATE_VERTICES {
            return Err(TemplateError::TooLarge {
                count: mesh.vertex_count(),
                max: MAX_TEMPLATE_VERTICES,
            });
        }
        let s = fit_sphere_robust(&mesh.vertices).ok();
        let unit =
            s.filter(|s| s.center_point().coords.norm() <= 0.25 && (s.radius - 1.0).abs() <= 0.25);
        let Some(unit) = unit else {
            return Err(TemplateError::NotUnit {
                center: s.map_or([f64::NAN; 3], |s| s.center),
                radius: s.map_or(f64::NAN, |s| s.radius),
            });
        };
        // Outward by the right-hand rule, as the method's normals and guards take a surface:
        // the share of the area whose triangles face the sphere's centre.
        let centre = unit.center_point();
        let (mut inward, mut total) = (0.0, 0.0);
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            let n = (b - a).cross(&(c - a));
            let area = 0.5 * n.norm();
            total += area;
            if n.dot(&(a - centre)) < 0.0 {
                inward += area;
            }
        }
        if inward > 0.5 * total {
            return Err(TemplateError::Inward {
                share: inward / total,
            });
        }
        let t = Template::marked(mesh);
        if !t.on_rim.iter().any(|&r| r) {
            return Err(TemplateError::NoRim);
        }
        Ok(t)
    }

    fn marked(mesh: Mesh) -> Template {
        let mut on_rim = vec![false; mesh.vertex_count()];
        for [a, b] in mesh.boundary_edges() {
            on_rim[a as usize] = true;
            on_rim[b as usize] = true;
        }
        Template { mesh, on_rim }
    }

    /// The mesh in the local frame.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Per vertex: does it lie on the rim (a border edge)?
    pub fn on_rim(&self) -> &[bool] {
        &self.on_rim
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn the_standard_cap_and_an_own_template_are_taken_and_bad_ones_named() {
        let t = Template::cap(&TemplateParams::default()).unwrap();
        assert!(t.on_rim().iter().filter(|&&r| r).count() > 50);
        // An embedder's own: the same cap, slightly flattened, is a template.
        let mut own = t.mesh().clone();
        for v in &mut own.vertices {
            v.z *= 0.9;
        }
        assert!(Template::new(own).is_ok());
        // Companions: in millimetres, or shifted off the origin, or closed, it is not.
        let mm = t
            .mesh()
            .transformed(26.0, &nalgebra::Rotation3::identity(), &Vector3::zeros());
        assert!(matches!(
            Template::new(mm),
            Err(TemplateError::NotUnit { .. })
        ));
        let shifted = t.mesh().transformed(
            1.0,
            &nalgebra::Rotation3::identity(),
            &Vector3::new(0.0, 0.0, 1.0),
        );
        assert!(matches!(
            Template::new(shifted),
            Err(TemplateError::NotUnit { .. })
        ));
        let v = |x, y, z| nalgebra::Point3::new(x, y, z);
        let octahedron = Mesh::new(
            vec![
                v(1.0, 0.0, 0.0),
                v(-1.0, 0.0, 0.0),
                v(0.0, 1.0, 0.0),
                v(0.0, -1.0, 0.0),
                v(0.0, 0.0, 1.0),
                v(0.0, 0.0, -1.0),
            ],
            vec![
                [0, 2, 4],
                [2, 1, 4],
                [1, 3, 4],
                [3, 0, 4],
                [2, 0, 5],
                [1, 2, 5],
                [3, 1, 5],
                [0, 3, 5],
            ],
        )
        .unwrap();
        assert_eq!(Template::new(octahedron), Err(TemplateError::NoRim));
        // A mesh whose public fields were filled in directly is checked as `Mesh::new` checks
        // one (a corner that is no vertex panicked), its normals made when it has none, and
        // one wound the other way round is named.
        let mut corner = t.mesh().clone();
        corner.triangles[0][0] = 1_000_000;
        assert!(matches!(
            Template::new(corner),
            Err(TemplateError::Mesh(
                crate::geom::MeshError::IndexOutOfRange { .. }
            ))
        ));
        let mut flipped = t.mesh().clone();
        for tri in &mut flipped.triangles {
            tri.swap(1, 2);
        }
        assert!(matches!(
            Template::new(flipped),
            Err(TemplateError::Inward { share }) if share > 0.99
        ));
        let mut bare = t.mesh().clone();
        bare.normals.clear();
        assert_eq!(Template::new(bare).unwrap().mesh(), t.mesh());
        for (field, p) in [
            (
                "polar_deg",
                TemplateParams {
                    polar_deg: 180.0,
                    ..Default::default()
                },
            ),
            (
                "polar_deg",
                TemplateParams {
                    polar_deg: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "vertices",
                TemplateParams {
                    vertices: usize::MAX,
                    ..Default::default()
                },
            ),
        ] {
            match Template::cap(&p) {
                Err(TemplateError::Setting { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {other:?}"),
            }
        }
        let edge = TemplateParams {
            polar_deg: 179.0,
            vertices: 3000,
        };
        assert!(Template::cap(&edge).is_ok());
    }
}
