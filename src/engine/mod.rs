//! The engine: where the per-iteration kernels run. `Kernels` dispatches each call to the CPU
//! (f64, the reference) or the GPU (the WGSL kernels in f32, `gpu`), whose CPU twins (`cpu`) run
//! the same loops for the kernel tests and the bench. The solver itself always runs on the CPU.

pub mod cpu;
pub mod gpu;

use crate::contours::{
    exact_points, silhouette_contour, ContourError, ContourSource, ModelContour,
};
use crate::engine::cpu::deform::DeformBatch;
use crate::engine::cpu::project::ViewRows;
use crate::engine::cpu::silhouette::{edges, rasterise, trace, Window};
use crate::engine::gpu::{Gpu, GpuBatcher, GpuError};
use crate::geom::Mesh;
use crate::solve::DeformationGraph;
use crate::views::{Camera, ProjectionError};
use nalgebra::{Point2, Point3};

/// The user's choice on the command line: `Cpu` (f64, the reference), `Gpu` (the WGSL
/// kernels) or `Auto`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
// The two plain choices are documented above: a doc comment on them would become help text in
// the command line's --help.
#[allow(missing_docs)]
pub enum BackendChoice {
    Cpu,
    Gpu,
    /// The GPU when an adapter exists, else the CPU (saying so in one line).
    Auto,
}

/// The kernels a reconstruction calls.
#[derive(Clone, Copy)]
pub enum Kernels<'g> {
    /// Every kernel on the CPU.
    Cpu,
    /// The GPU kernels on the caller's device.
    Gpu(&'g Gpu<'g>),
    /// The GPU, with requests merged across concurrent runs (the study's GPU path).
    Batched(&'g GpuBatcher<'g>),
}

/// Why a kernel call failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum KernelError {
    /// The GPU kernel failed.
    #[error("GPU: {0}")]
    Gpu(#[from] GpuError),
    /// No model contour could be found in a view.
    #[error("view {view}: model contour: {source}")]
    Contour {
        /// The view.
        view: usize,
        /// Why.
        source: ContourError,
    },
}

/// Silhouette texture size (texels per side).
pub const SILHOUETTE_TEXELS: u32 = 512;

impl Kernels<'_> {
    /// `f(k, &items[k])` for the independent parts of one run (views, resamples, starts), in
    /// input order: side by side on the CPU (`geom::par_map`); on the batched GPU each on a
    /// thread of its own registered with the batcher in the run's place (`GpuBatcher::parts`),
    /// so their device requests join the same lock-step dispatches; one after the other on the
    /// plain GPU path.
    pub fn map_parts<T: Sync, R: Send>(
        &self,
        items: &[T],
        f: impl Fn(usize, &T) -> R + Sync + Send,
    ) -> Vec<R> {
        match self {
            Kernels::Cpu => crate::geom::par_map(items, f),
            Kernels::Batched(b) => b.parts(items, f),
            Kernels::Gpu(_) => items.iter().enumerate().map(|(k, t)| f(k, t)).collect(),
        }
    }

    /// One panel of a surface picture (`report::plots::surface_views`): rendered on the GPU
    /// (`shaders/surface.wgsl`), or by its CPU twin on the CPU and wherever the GPU cannot;
    /// the pixels and which drew them ("gpu" or "cpu").
    pub fn render_surface(
        &self,
        p: &crate::report::SurfacePanel,
    ) -> (crate::report::PanelPixels, &'static str) {
        let view = crate::engine::cpu::surface::SurfaceView::looking(
            &p.center,
            &p.look,
            &p.up_hint,
            p.px_per_mm,
            p.extent_mm,
            p.size,
        );
        let gpu = match self {
            Kernels::Cpu => None,
            Kernels::Gpu(g) => Some(*g),
            Kernels::Batched(b) => Some(b.gpu()),
        };
        if let Some(Ok(px)) = gpu.map(|g| g.render_surface(p.points, p.colors, p.triangles, &view))
        {
            return (px, "gpu");
        }
        (
            crate::engine::cpu::surface::render_surface(p.points, p.colors, p.triangles, &view),
            "cpu",
        )
    }

    /// Where a run's SRVF DPs go: the device, through the study's batcher when it was built
    /// with `GpuBatcher::with_dp_on_device`; the host otherwise.
    pub fn dp(&self) -> crate::correspond::srvf::DpOn<'_> {
        match self {
            Kernels::Batched(b) if b.dp_on_device() => crate::correspond::srvf::DpOn::Device(*b),
            _ => crate::correspond::srvf::DpOn::Host,
        }
    }

    /// "cpu" or "gpu".
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
        let b = DeformBatch::from_graphs(&[(graph, x)]).map_err(GpuError::from)?;
        let displacement = match self {
            Kernels::Batched(g) => g.deform(b)?,
            Kernels::Gpu(g) => g.deform(&b)?,
            Kernels::Cpu => unreachable!("returned above"),
        };
        Ok(crate::engine::cpu::deform::positions(
            &graph.rest,
            &displacement,
        ))
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
            Kernels::Cpu => crate::engine::cpu::project::project(&v, v.len(), &rows),
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
            // Alpha shapes are a CPU algorithm (delaunator's Delaunay) on f64 projections for every
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
