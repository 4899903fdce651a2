//! Each kernel: CPU twin vs GPU (including upload and read-back), at several sizes. Without a
//! GPU adapter only the CPU twins are measured (and a line says so).

use acetab::correspond::srvf::{coprime_steps, srvf};
use acetab::engine::cpu::{
    deform as cdeform, project as cproject, silhouette as csil, srvf_dp as cdp,
};
use acetab::engine::gpu::GpuDevice;
use acetab::sim::{simulated_views, XrayGeometry};
use acetab::solve::{DeformationGraph, GraphParams};
use acetab::template::hemisphere;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::{Point2, Point3};

fn bench(c: &mut Criterion) {
    let dev = match GpuDevice::from_env() {
        Ok(d) => Some(d),
        Err(e) => {
            eprintln!("kernels bench: {e}; measuring the CPU twins only");
            None
        }
    };
    let gpu = dev.as_ref().map(|d| d.engine().expect("pipelines compile"));
    let mut g = c.benchmark_group("kernels");
    g.sample_size(10);
    for nv in [1_000usize, 10_000, 100_000] {
        let mesh = hemisphere(26.0, nv);
        let graph = DeformationGraph::new(&mesh, &GraphParams::default());
        let x = graph.identity();
        let batch = cdeform::DeformBatch::from_graphs(&[(&graph, &x)]).unwrap();
        g.bench_with_input(BenchmarkId::new("deform/cpu", nv), &batch, |b, batch| {
            b.iter(|| cdeform::deform(batch))
        });
        if let Some(gpu) = &gpu {
            g.bench_with_input(BenchmarkId::new("deform/gpu", nv), &batch, |b, batch| {
                b.iter(|| gpu.deform(batch).unwrap())
            });
        }
        let verts: Vec<[f32; 4]> = mesh
            .vertices
            .iter()
            .map(|q| [q.x as f32, q.y as f32, q.z as f32, 0.0])
            .collect();
        let views: Vec<cproject::ViewRows> =
            simulated_views(&XrayGeometry::default(), &Point3::origin())
                .iter()
                .map(cproject::ViewRows::from_camera)
                .collect();
        g.bench_with_input(BenchmarkId::new("project/cpu", nv), &verts, |b, v| {
            b.iter(|| cproject::project(v, v.len(), &views))
        });
        if let Some(gpu) = &gpu {
            g.bench_with_input(BenchmarkId::new("project/gpu", nv), &verts, |b, v| {
                b.iter(|| gpu.project(v, v.len(), &views).unwrap())
            });
        }
        let tris: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
        let proj = cproject::project(&verts, verts.len(), &views[..1]);
        let w = csil::Window::around(&proj, 512).unwrap();
        g.bench_with_input(BenchmarkId::new("silhouette/cpu", nv), &proj, |b, p| {
            b.iter(|| csil::trace(&csil::edges(&csil::rasterise(p, &tris, &w), w.size), w.size))
        });
        if let Some(gpu) = &gpu {
            g.bench_with_input(BenchmarkId::new("silhouette/gpu", nv), &proj, |b, p| {
                b.iter(|| gpu.silhouette_of_projected(p, &tris, &w).unwrap())
            });
        }
    }
    let n = 64;
    let curve = |f: f64, ph: f64| -> Vec<Point2<f64>> {
        (0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64 * 3.0;
                Point2::new(t, (f * t + ph).sin())
            })
            .collect()
    };
    let steps = coprime_steps(5);
    for problems in [1usize, 16, 256, 1024] {
        let qs: Vec<_> = (0..problems)
            .map(|k| {
                (
                    srvf(&curve(2.0, 0.0), false),
                    srvf(&curve(2.0 + 0.01 * k as f64, 0.3), false),
                )
            })
            .collect();
        let pairs: Vec<_> = qs.iter().map(|(a, b)| (&a[..], &b[..])).collect();
        let batch = cdp::DpBatch::new(&pairs, &steps).unwrap();
        g.bench_with_input(
            BenchmarkId::new("srvf_dp/cpu", problems),
            &batch,
            |b, batch| b.iter(|| cdp::dp_tables(batch)),
        );
        if let Some(gpu) = &gpu {
            g.bench_with_input(
                BenchmarkId::new("srvf_dp/gpu", problems),
                &batch,
                |b, batch| b.iter(|| gpu.srvf_dp_tables(batch).unwrap()),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
