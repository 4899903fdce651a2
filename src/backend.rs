//! Where the per-iteration kernels run: the CPU (f64, the reference) or the GPU (the WGSL
//! kernels in f32 through `crate::gpu`). The solver itself always runs on the CPU.

use crate::contours::{signed_area, ContourError, ModelContour};
use crate::cpu::deform::DeformBatch;
use crate::cpu::project::ViewRows;
use crate::cpu::silhouette::{edges, rasterise, trace, Window};
use crate::gpu::{Gpu, GpuBatcher, GpuError};
use crate::mesh::Mesh;
use crate::solve::DeformationGraph;
use crate::views::{Camera, ProjectionError};
use nalgebra::{Point2, Point3};

/// The user's choice on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendChoice {
    Cpu,
    Gpu,
    /// The GPU when an adapter exists, else the CPU (saying so in one line).
    Auto,
}

/// How the model contour of each view is found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ContourSource {
    /// Alpha shape of the projected vertices (spade Delaunay).
    #[default]
    AlphaShape,
    /// Rasterised silhouette (render pass + edge kernel on the GPU, its twin on the CPU).
    Silhouette,
}

/// The kernels a reconstruction calls.
#[derive(Clone, Copy)]
pub enum Kernels<'g> {
    Cpu,
    Gpu(&'g Gpu<'g>),
    /// The GPU, with requests merged across concurrent runs (the study's GPU path).
    Batched(&'g GpuBatcher<'g>),
}

/// Why a kernel call failed.
#[derive(Debug, thiserror::Error)]
pub enum KernelError {
    #[error("GPU: {0}")]
    Gpu(#[from] GpuError),
    #[error("view {view}: model contour: {source}")]
    Contour { view: usize, source: ContourError },
}

/// Silhouette texture size (texels per side).
pub const SILHOUETTE_TEXELS: u32 = 512;

impl Kernels<'_> {
    pub fn name(&self) -> &'static str {
        match self {
            Kernels::Cpu => "cpu",
            Kernels::Gpu(_) | Kernels::Batched(_) => "gpu",
        }
    }

    /// Deformed vertices of the graph's mesh for parameters x.
    pub fn deform(
        &self,
        graph: &DeformationGraph,
        x: &[f64],
    ) -> Result<Vec<Point3<f64>>, KernelError> {
        if let Kernels::Cpu = self {
            return Ok(graph.deform(x));
        }
        let b = DeformBatch::from_graphs(&[(graph, x)]).map_err(|e| GpuError::Input {
            kernel: "deform",
            message: e.to_string(),
        })?;
        let displacement = match self {
            Kernels::Batched(g) => g.deform(b)?,
            Kernels::Gpu(g) => g.deform(&b)?,
            Kernels::Cpu => unreachable!("returned above"),
        };
        Ok(crate::cpu::deform::positions(&graph.rest, &displacement))
    }

    /// Projected vertices (u, v, depth, valid) per view, in f32 as the kernels produce them.
    fn project_f32(&self, mesh: &Mesh, cams: &[Camera]) -> Result<Vec<Vec<[f32; 4]>>, KernelError> {
        let v: Vec<[f32; 4]> = mesh
            .vertices
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
            .collect();
        let rows: Vec<ViewRows> = cams.iter().map(ViewRows::from_camera).collect();
        let all = match self {
            Kernels::Cpu => crate::cpu::project::project(&v, v.len(), &rows),
            Kernels::Gpu(g) => g.project(&v, v.len(), &rows)?,
            Kernels::Batched(g) => g.project(v.clone(), v.len(), rows)?,
        };
        Ok(all.chunks(v.len().max(1)).map(|c| c.to_vec()).collect())
    }

    /// The model contour of `mesh` in every view.
    pub fn contours(
        &self,
        mesh: &Mesh,
        cams: &[Camera],
        source: ContourSource,
    ) -> Result<Vec<ModelContour>, KernelError> {
        match (self, source) {
            // Alpha shapes are a CPU algorithm (spade's Delaunay) on f64 projections for every
            // backend: on a projected near-regular grid many point quadruples are nearly
            // cocircular, and the last bits of an f32 projection flip Delaunay and alpha
            // decisions, so GPU projections would make the backends disagree. The GPU projects
            // for the silhouette path, where its raster needs the projections on the device.
            (_, ContourSource::AlphaShape) => crate::contours::model_contours(mesh, cams)
                .into_iter()
                .enumerate()
                .map(|(view, c)| c.map_err(|source| KernelError::Contour { view, source }))
                .collect(),
            (_, ContourSource::Silhouette) => {
                let per_view = self.project_f32(mesh, cams)?;
                let tris: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
                per_view
                    .iter()
                    .enumerate()
                    .map(|(view, proj)| {
                        let pts = valid_points(proj)
                            .map_err(|source| KernelError::Contour { view, source })?;
                        let window = Window::around(proj, SILHOUETTE_TEXELS).ok_or(
                            KernelError::Contour {
                                view,
                                source: ContourError::TooFewPoints { count: 0 },
                            },
                        )?;
                        let ids = match self {
                            Kernels::Cpu => trace(
                                &edges(&rasterise(proj, &tris, &window), window.size),
                                window.size,
                            ),
                            Kernels::Gpu(g) => {
                                g.silhouette_of_projected(proj, &tris, &window)?.contour
                            }
                            Kernels::Batched(g) => {
                                g.gpu()
                                    .silhouette_of_projected(proj, &tris, &window)?
                                    .contour
                            }
                        };
                        let c = silhouette_contour(&ids, &pts)
                            .map_err(|source| KernelError::Contour { view, source })?;
                        exact_points(c, mesh, &cams[view])
                            .map_err(|source| KernelError::Contour { view, source })
                    })
                    .collect()
            }
        }
    }
}

/// The kernels choose the contour's vertices; their positions are re-projected in f64 so that
/// the correspondence stage sees the same numbers on either backend.
fn exact_points(
    mut c: ModelContour,
    mesh: &Mesh,
    cam: &Camera,
) -> Result<ModelContour, ContourError> {
    for (p, &id) in c.points.iter_mut().zip(&c.vertex_ids) {
        *p = cam.project(&mesh.vertices[id as usize]).map_err(|source| {
            ContourError::Projection {
                vertex: id as usize,
                source,
            }
        })?;
    }
    Ok(c)
}

/// f64 points of valid projections; a vertex behind the source is the same error as on the
/// CPU path.
fn valid_points(proj: &[[f32; 4]]) -> Result<Vec<Point2<f64>>, ContourError> {
    proj.iter()
        .enumerate()
        .map(|(vertex, p)| {
            if p[3] > 0.5 {
                Ok(Point2::new(p[0] as f64, p[1] as f64))
            } else {
                Err(ContourError::Projection {
                    vertex,
                    source: ProjectionError::BehindCamera { depth: p[2] as f64 },
                })
            }
        })
        .collect()
}

/// A model contour from a traced loop of vertex ids, turned to positive signed area.
pub fn silhouette_contour(ids: &[u32], pts: &[Point2<f64>]) -> Result<ModelContour, ContourError> {
    if ids.len() < 3 {
        return Err(ContourError::TooFewPoints { count: ids.len() });
    }
    let mut vertex_ids = ids.to_vec();
    let mut points: Vec<Point2<f64>> = ids.iter().map(|&i| pts[i as usize]).collect();
    if signed_area(&points) < 0.0 {
        vertex_ids.reverse();
        points.reverse();
    }
    Ok(ModelContour { vertex_ids, points })
}
