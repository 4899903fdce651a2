//! Simulated cases: project a ground-truth surface into the X-ray views, take the alpha-shape
//! contours with Gaussian pixel noise as the "annotations", and perturb the template's start
//! from the truth's fitted hemisphere by a noise level. Every draw comes from one seeded RNG.

use crate::contours::{model_contour, ContourError};

use crate::geom::Curve;
use crate::geom::Mesh;
use crate::geom::{fit_sphere, Sphere, SphereFitError};
use crate::pipeline::Input;
use crate::sim::{simulated_views, GeometryError, XrayGeometry};
use crate::template::{Placement, Template};
use crate::views::Camera;
use nalgebra::{Point2, Point3, Rotation3, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// Initialisation noise of one level: Euler-angle SD (rad), translation SD per axis (mm) and the
/// scale factor s (scale = exp(N(0, ln s))).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct NoiseLevel {
    /// Rotation SD, rad.
    pub rotation_sd: f64,
    /// Translation SD per axis, mm.
    pub translation_sd: f64,
    /// Scale factor s.
    pub scale: f64,
}

impl NoiseLevel {
    /// The paper's levels 1..5 (level 0: no initialisation noise).
    pub fn level(l: u32) -> Option<NoiseLevel> {
        let t = [
            (0.0, 0.0, 1.0),
            (0.1, 10.0, 1.1),
            (0.2, 30.0, 1.2),
            (0.3, 50.0, 1.3),
            (0.4, 80.0, 1.4),
            (0.5, 100.0, 1.5),
        ];
        t.get(l as usize).map(|&(r, tr, s)| NoiseLevel {
            rotation_sd: r,
            translation_sd: tr,
            scale: s,
        })
    }
}

/// A simulated case.
#[derive(Clone, Debug)]
pub struct SimCase {
    /// The views.
    pub cameras: Vec<Camera>,
    /// Per view, the noisy observed outline.
    pub observed: Vec<Vec<Curve>>,
    /// The hemisphere fitted to the truth (before perturbation).
    pub truth_placement: Placement,
    /// The truth's sphere.
    pub truth_sphere: Sphere,
    /// The perturbed start.
    pub init: Placement,
    /// The seed of this case's draws.
    pub seed: u64,
    /// Per view, the simulated annotator's clicks, where it clicked (`RealisticErrors::click_px`
    /// read as clicks, whose curve `observed` carries); empty otherwise. The overlays mark them.
    pub clicks: Vec<Vec<Point2<f64>>>,
}

impl SimCase {
    /// The reconstruction's input: this case's views, outlines and perturbed start, with
    /// `template`.
    pub fn input<'a>(&'a self, template: &'a Template) -> Input<'a> {
        Input::new(&self.cameras, &self.observed, &self.init, template)
    }
}

/// Why a truth cannot be simulated or a setting is refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// No sphere fits the ground truth.
    #[error("ground truth sphere fit: {0}")]
    Sphere(#[from] SphereFitError),
    /// The ground truth is not a mesh (its fields are public): a triangle corner that is no
    /// vertex, a non-finite coordinate, no area (`Mesh::check`).
    #[error("ground truth mesh: {0}")]
    Mesh(crate::geom::MeshError),
    /// The ground truth's outer side could not be cut out.
    #[error("ground truth outer side: {0}")]
    Surface(crate::geom::MeshError),
    /// The ground truth casts no outline in a view.
    #[error("ground truth contour in view {view}: {source}")]
    Contour {
        /// The view.
        view: usize,
        /// Why.
        source: ContourError,
    },
    /// A simulated annotation keeps too few points: the realistic protocol's left-out arc,
    /// click spacing or mask grid thin the view's outline below what a curve needs.
    #[error(
        "simulated annotation in view {view}: {count} points left of the outline's {outline} \
         (left_out {left_out}, click_px {click_px}, raster_px {raster_px}); at least {min} are \
         needed: the realistic settings thin the outline too far"
    )]
    Annotation {
        /// The view.
        view: usize,
        /// Points the annotation kept.
        count: usize,
        /// Points of the truth's outline in the view.
        outline: usize,
        /// The share of the outline left out.
        left_out: f64,
        /// The click spacing, px (0: the outline's own points).
        click_px: f64,
        /// The mask grid's pitch, px (0: none).
        raster_px: f64,
        /// The fewest points an annotation keeps.
        min: usize,
    },
    /// The simulated view geometry is unusable.
    #[error("{0}")]
    Geometry(#[from] GeometryError),
    /// A simulation setting no draw can be made with.
    #[error("{field} = {value}: must be {expected}")]
    Setting {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
    /// The reconstruction settings are refused.
    #[error("reconstruction settings: {0}")]
    Params(#[from] crate::pipeline::ReconError),
}

/// A Gaussian with this SD, or the setting's error (NaN, infinite or negative).
pub(super) fn gaussian(field: &'static str, sd: f64) -> Result<Normal<f64>, SimError> {
    Normal::new(0.0, sd)
        .ok()
        .filter(|_| sd.is_finite() && sd >= 0.0)
        .ok_or(SimError::Setting {
            field,
            value: crate::io::shown(&sd.to_string()),
            expected: "a finite SD >= 0",
        })
}

/// The hemisphere that best fits a surface: the sphere fit's centre and radius, the opening axis
/// pointing from the surface's centroid through the centre.
pub fn fit_placement(truth: &Mesh) -> Result<(Placement, Sphere), SphereFitError> {
    let s = fit_sphere(&truth.vertices)?;
    let c = s.center_point();
    let axis = crate::geom::opening_axis(&truth.vertices, &c);
    Ok((
        Placement {
            center: c,
            radius: s.radius,
            axis,
        },
        s,
    ))
}

/// The ground-truth surface of a mesh: a closed shell (no boundary edges, like the cartilage
/// shells in ../shared) is reduced to its outer side, the faces whose normal points away from the
/// fitted sphere centre; an open surface is used as it is.
pub fn ground_truth_surface(mesh: &Mesh) -> Result<Mesh, SimError> {
    if !mesh.boundary_edges().is_empty() {
        return Ok(mesh.clone());
    }
    let c = fit_sphere(&mesh.vertices)?.center_point();
    let keep: Vec<usize> = (0..mesh.triangles.len())
        .filter(|&t| {
            let [a, b, d] = mesh.triangles[t].map(|i| mesh.vertices[i as usize]);
            let n = (b - a).cross(&(d - a));
            n.dot(&((a.coords + b.coords + d.coords) / 3.0 - c.coords)) > 0.0
        })
        .collect();
    mesh.submesh(&keep).map_err(SimError::Surface)
}

/// Alpha radius (pixels) of the simulated annotation: concavities narrower than half the
/// acetabulum's radius (the notch, the fossa of a horseshoe-shaped cartilage surface, gaps between
/// mesh vertices) are bridged, as an annotator tracing the bony outline on an X-ray bridges them.
/// Never below the mesh-resolution default.
pub fn observed_alpha(truth: &Mesh, cam: &Camera, placement: &Placement) -> f64 {
    let projected: Vec<_> = truth
        .vertices
        .iter()
        .filter_map(|v| cam.project(v).ok())
        .collect();
    let by_edges = if projected.len() == truth.vertex_count() {
        crate::contours::default_alpha(truth, &projected)
    } else {
        0.0
    };
    by_edges
        .max(OBSERVED_ALPHA_FRACTION * placement.radius * cam.pixels_per_mm_at(&placement.center))
}

/// See `observed_alpha`.
pub const OBSERVED_ALPHA_FRACTION: f64 = 0.5;

/// Perturb a placement: the axis rotated by Euler angles (x, y, z) drawn with the level's SD, the
/// centre shifted per axis, the radius scaled.
/// A level whose SDs are not finite and >= 0, or whose scale is not finite and >= 1, is an error.
pub fn perturb(
    p: &Placement,
    level: &NoiseLevel,
    rng: &mut impl rand::Rng,
) -> Result<Placement, SimError> {
    let nr = gaussian("noise level rotation_sd", level.rotation_sd)?;
    let nt = gaussian("noise level translation_sd", level.translation_sd)?;
    if !(level.scale.is_finite() && level.scale >= 1.0) {
        return Err(SimError::Setting {
            field: "noise level scale",
            value: crate::io::shown(&level.scale.to_string()),
            expected: "finite and >= 1",
        });
    }
    let ns = gaussian("noise level scale", level.scale.ln())?;
    let (ax, ay, az) = (nr.sample(rng), nr.sample(rng), nr.sample(rng));
    let rot = Rotation3::from_euler_angles(ax, ay, az);
    let t = Vector3::new(nt.sample(rng), nt.sample(rng), nt.sample(rng));
    let s = ns.sample(rng).exp();
    Ok(Placement {
        center: p.center + t,
        radius: p.radius * s,
        axis: rot * p.axis,
    })
}

/// What every run of a study shares: the truth's fitted hemisphere, the views aimed at it and
/// the truth's noise-free outlines. `case` adds one run's noise and start.
#[derive(Clone, Debug)]
pub struct SimSetup {
    /// The hemisphere fitted to the truth.
    pub placement: Placement,
    /// The truth's sphere.
    pub sphere: Sphere,
    /// The views, aimed at its centre.
    pub cameras: Vec<Camera>,
    /// The truth's alpha-shape outline per view, before noise.
    pub outlines: Vec<Vec<nalgebra::Point2<f64>>>,
    /// The truth's vertices that form those outlines, in any view (sorted, once each).
    pub outline_vertices: Vec<u32>,
}

impl SimSetup {
    /// The set-up of `truth` in `geometry`'s views.
    pub fn new(truth: &Mesh, geometry: &XrayGeometry) -> Result<SimSetup, SimError> {
        geometry.validate()?;
        truth.check().map_err(SimError::Mesh)?;
        let (placement, sphere) = fit_placement(truth)?;
        let cameras = simulated_views(geometry, &placement.center);
        let mut outlines = Vec::new();
        let mut outline_vertices = Vec::new();
        for (view, cam) in cameras.iter().enumerate() {
            let c = model_contour(truth, cam, Some(observed_alpha(truth, cam, &placement)))
                .map_err(|source| SimError::Contour { view, source })?;
            outlines.push(c.points);
            outline_vertices.extend(c.vertex_ids);
        }
        outline_vertices.sort_unstable();
        outline_vertices.dedup();
        Ok(SimSetup {
            placement,
            sphere,
            cameras,
            outlines,
            outline_vertices,
        })
    }

    /// The sphere (robust fit, as the cup's) through the truth's own outline-forming vertices:
    /// the most a sphere read from these views' outlines can know of the truth. Its diameter
    /// minus the truth's cup (`sphere`) is a floor under any outline-based cup estimate's error
    /// for this truth, before noise. `truth` is the mesh the set-up was made from.
    pub fn outline_sphere(&self, truth: &Mesh) -> Result<Sphere, SphereFitError> {
        let pts: Vec<Point3<f64>> = self
            .outline_vertices
            .iter()
            .filter_map(|&i| truth.vertices.get(i as usize).copied())
            .collect();
        crate::geom::fit_sphere_robust(&pts)
    }

    /// One run: Gaussian noise of `noise_px` on every outline point, the start perturbed by
    /// `level`; all draws from ChaCha8(seed). A noise SD that is not finite and >= 0 is an error.
    pub fn case(&self, noise_px: f64, level: &NoiseLevel, seed: u64) -> Result<SimCase, SimError> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = gaussian("contour noise (px)", noise_px)?;
        let observed = self
            .outlines
            .iter()
            .map(|pts| {
                let points = pts
                    .iter()
                    .map(|p| {
                        nalgebra::Point2::new(
                            p.x + noise.sample(&mut rng),
                            p.y + noise.sample(&mut rng),
                        )
                    })
                    .collect();
                vec![Curve {
                    points,
                    closed: true,
                }]
            })
            .collect();
        let init = perturb(&self.placement, level, &mut rng)?;
        Ok(self.case_of(observed, init, seed))
    }

    /// A case in this set-up's nominal views with these outlines and start.
    pub(super) fn case_of(&self, observed: Vec<Vec<Curve>>, init: Placement, seed: u64) -> SimCase {
        SimCase {
            clicks: vec![Vec::new(); observed.len()],
            cameras: self.cameras.clone(),
            observed,
            truth_placement: self.placement.clone(),
            truth_sphere: self.sphere,
            init,
            seed,
        }
    }
}

/// Simulate: views aimed at the truth's sphere centre, alpha-shape contours with `noise_px`
/// Gaussian noise per point, start perturbed by `level`; all draws from ChaCha8(seed).
pub fn simulate_case(
    truth: &Mesh,
    geometry: &XrayGeometry,
    noise_px: f64,
    level: &NoiseLevel,
    seed: u64,
) -> Result<SimCase, SimError> {
    SimSetup::new(truth, geometry)?.case(noise_px, level, seed)
}

/// Views with pose errors: every view except `reference` is turned by `deg` degrees about a
/// random axis through `center` and shifted by `mm` in a random direction (seeded). The
/// reference view defines the frame, as the AP view does in practice.
pub fn perturb_poses(
    cams: &[Camera],
    center: &Point3<f64>,
    deg: f64,
    mm: f64,
    reference: usize,
    seed: u64,
) -> Vec<Camera> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x9E37_79B9_7F4A_7C15);
    let unit = |rng: &mut rand_chacha::ChaCha8Rng| loop {
        let mut n = || -> f64 { rand_distr::StandardNormal.sample(rng) };
        let v = Vector3::new(n(), n(), n());
        if v.norm() > 1e-6 {
            break v.normalize();
        }
    };
    cams.iter()
        .enumerate()
        .map(|(k, c)| {
            if k == reference {
                return c.clone();
            }
            let w = unit(&mut rng) * deg.to_radians();
            let t = unit(&mut rng) * mm;
            crate::solve::corrected_camera(c, center, &[w.x, w.y, w.z, t.x, t.y, t.z])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{phantom, PhantomParams};

    /// A truth whose public fields were filled in wrongly is named: a triangle corner that is
    /// no vertex panicked (in the contour of the truth, as in `model_contour` of any such
    /// mesh), a NaN vertex was "the points are degenerate". Companion: the phantom sets up.
    #[test]
    fn a_truth_that_is_not_a_mesh_is_named() {
        let truth = phantom(&PhantomParams::default()).mesh;
        let setup = SimSetup::new(&truth, &XrayGeometry::default()).unwrap();
        let cam = &setup.cameras[0];
        assert!(crate::contours::model_contour(&truth, cam, None).is_ok());
        let mut corner = truth.clone();
        corner.triangles[0][1] = 10_000_000;
        assert!(matches!(
            crate::contours::model_contour(&corner, cam, None),
            Err(crate::contours::ContourError::Mesh(_))
        ));
        let mut nan = truth.clone();
        nan.vertices[3].x = f64::NAN;
        for bad in [corner, nan] {
            assert!(matches!(
                SimSetup::new(&bad, &XrayGeometry::default()),
                Err(SimError::Mesh(_))
            ));
        }
    }

    #[test]
    fn the_outline_sphere_finds_a_sphere_and_misses_what_the_views_do_not_see() {
        let place = Placement {
            center: Point3::new(80.0, 10.0, -500.0),
            radius: 26.0,
            axis: nalgebra::Unit::new_normalize(Vector3::new(1.0, 0.3, -0.8)),
        };
        let cap = place.place(&crate::template::spherical_cap(
            1.0,
            3000,
            85f64.to_radians(),
        ));
        let setup = SimSetup::new(&cap, &XrayGeometry::default()).unwrap();
        let d = setup.outline_sphere(&cap).unwrap().diameter() - setup.sphere.diameter();
        assert!(d.abs() < 0.05, "sphere: {d}");
        // The same cap 6 % deeper along y (towards the AP source), which no view turned about
        // z sees in outline: the outline sphere stays near the unstretched one, the truth's
        // cup grows.
        let c = place.center;
        let deep = cap.with_vertices(
            cap.vertices
                .iter()
                .map(|v| Point3::new(v.x, c.y + 1.06 * (v.y - c.y), v.z))
                .collect(),
        );
        let setup = SimSetup::new(&deep, &XrayGeometry::default()).unwrap();
        let d = setup.outline_sphere(&deep).unwrap().diameter() - setup.sphere.diameter();
        assert!(d < -0.5, "stretched in depth: {d}");
    }

    #[test]
    fn a_noise_no_gaussian_has_is_an_error_not_a_panic() {
        let truth = phantom(&PhantomParams::default()).mesh;
        let setup = SimSetup::new(&truth, &XrayGeometry::default()).unwrap();
        let level = NoiseLevel::level(2).unwrap();
        for noise in [f64::INFINITY, f64::NAN, -1.0] {
            assert!(matches!(
                setup.case(noise, &level, 1),
                Err(SimError::Setting { .. })
            ));
        }
        for bad in [
            NoiseLevel {
                rotation_sd: f64::INFINITY,
                ..level
            },
            NoiseLevel {
                translation_sd: -1.0,
                ..level
            },
            NoiseLevel {
                scale: 0.5,
                ..level
            },
            NoiseLevel {
                scale: f64::NAN,
                ..level
            },
        ] {
            assert!(matches!(
                setup.case(2.0, &bad, 1),
                Err(SimError::Setting { .. })
            ));
        }
        // Companion: no noise at all is a valid case, and the same seed gives the same case.
        let a = setup.case(0.0, &NoiseLevel::level(0).unwrap(), 7).unwrap();
        assert_eq!(a.observed[0][0].points, setup.outlines[0]);
        let b = setup.case(2.0, &level, 7).unwrap();
        let c = setup.case(2.0, &level, 7).unwrap();
        assert_eq!(b.observed[1][0].points, c.observed[1][0].points);
        assert_ne!(b.observed[1][0].points, setup.outlines[1]);
    }
}
