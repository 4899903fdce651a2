//! Every GPU kernel against its CPU twin on the same inputs (outputs pre-filled with sentinels by
//! the engine), each comparison with a companion that feeds a perturbed result and must be
//! rejected; and a whole reconstruction on the GPU against the CPU.
//!
//! These run on whatever adapter wgpu finds (lavapipe in CI). Without one they fail with a clear
//! message; they skip only when ACETAB_SKIP_GPU=1 is set on purpose.

use acetab::engine::cpu::{
    deform as cdeform, project as cproject, silhouette as csil, srvf_dp as cdp,
};
use acetab::engine::gpu::{Gpu, GpuDevice};
use acetab::sim::{simulated_views, XrayGeometry};
use acetab::solve::{DeformationGraph, GraphParams};
use acetab::template::hemisphere;
use nalgebra::{Point3, Vector2};
use std::sync::OnceLock;

fn device() -> Option<&'static GpuDevice> {
    static DEV: OnceLock<Option<GpuDevice>> = OnceLock::new();
    DEV.get_or_init(|| {
        if std::env::var("ACETAB_SKIP_GPU").as_deref() == Ok("1") {
            eprintln!("ACETAB_SKIP_GPU=1: GPU tests skipped on purpose");
            return None;
        }
        match GpuDevice::from_env() {
            Ok(d) => {
                eprintln!("GPU tests on {}", d.describe());
                Some(d)
            }
            Err(e) => panic!(
                "no GPU adapter for the GPU tests: {e}. Install mesa-vulkan-drivers (lavapipe) or set ACETAB_SKIP_GPU=1 to skip them on purpose"
            ),
        }
    })
    .as_ref()
}

/// A mesh as the kernels take it: its vertices as (x, y, z, 0) and its triangles' corners.
fn mesh_buffers(mesh: &acetab::geom::Mesh) -> (Vec<[f32; 4]>, Vec<u32>) {
    let verts = mesh
        .vertices
        .iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
        .collect();
    (verts, mesh.triangles.iter().flatten().copied().collect())
}

/// Run `f` with the engine, or return (skipping) when ACETAB_SKIP_GPU=1.
fn with_gpu(f: impl FnOnce(&Gpu)) {
    let Some(d) = device() else { return };
    let gpu = d.engine().expect("pipelines compile");
    f(&gpu);
}

/// Largest absolute difference over all components; NaN (an unwritten sentinel) counts as
/// infinite.
fn max_abs_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    if a.len() != b.len() {
        return f32::INFINITY;
    }
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| (0..4).map(move |c| (x[c] - y[c]).abs()))
        .map(|d| if d.is_nan() { f32::INFINITY } else { d })
        .fold(0.0, f32::max)
}

fn graphs() -> Vec<(DeformationGraph, Vec<f64>)> {
    (0..3)
        .map(|k| {
            let mesh = hemisphere(20.0 + 3.0 * k as f64, 1200);
            let mesh = mesh.transformed(
                1.0,
                &nalgebra::Rotation3::identity(),
                &nalgebra::Vector3::new(30.0 * k as f64, -20.0, 10.0),
            );
            let g = DeformationGraph::new(&mesh, &GraphParams::default());
            let mut x = g.identity();
            for (i, v) in x.iter_mut().enumerate() {
                *v += 0.02 * (((i * 7 + k * 13) % 11) as f64 - 5.0);
            }
            (g, x)
        })
        .collect()
}

/// Deform: |GPU - CPU twin| <= 1e-3 mm on coordinates of ~100 mm (f32, a few ulp per term).
const DEFORM_BOUND: f32 = 1e-3;

#[test]
fn deform_matches_its_cpu_twin() {
    with_gpu(|gpu| {
        let gs = graphs();
        let items: Vec<(&DeformationGraph, &[f64])> = gs.iter().map(|(g, x)| (g, &x[..])).collect();
        let batch = cdeform::DeformBatch::from_graphs(&items).unwrap();
        let cpu = cdeform::deform(&batch);
        let gpu_out = gpu.deform(&batch).unwrap();
        let d = max_abs_diff(&cpu, &gpu_out);
        assert!(d <= DEFORM_BOUND, "deform differs by {d} mm");
        // Companion: one coordinate off by 0.01 mm must be rejected.
        let mut wrong = gpu_out.clone();
        wrong[1234][1] += 0.01;
        assert!(max_abs_diff(&cpu, &wrong) > DEFORM_BOUND);
    });
}

/// Project: pixels within 0.01 px and depth within 1e-3 mm (f32 at ~10^3 px, ~10^3 mm; GPU
/// division may be 2.5 ulp).
fn project_ok(a: &[[f32; 4]], b: &[[f32; 4]]) -> Result<(), String> {
    if a.len() != b.len() {
        return Err(format!("lengths {} and {}", a.len(), b.len()));
    }
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let px = (x[0] - y[0]).abs().max((x[1] - y[1]).abs());
        if !(px <= 0.01 && (x[2] - y[2]).abs() <= 1e-3 && x[3] == y[3]) {
            return Err(format!("output {i}: {x:?} vs {y:?}"));
        }
    }
    Ok(())
}

#[test]
fn project_matches_its_cpu_twin() {
    with_gpu(|gpu| {
        let gs = graphs();
        let verts: Vec<[f32; 4]> = gs
            .iter()
            .flat_map(|(g, _)| {
                g.rest
                    .iter()
                    .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
            })
            .collect();
        let n = gs[0].0.rest.len();
        let mut cams = simulated_views(&XrayGeometry::default(), &Point3::new(30.0, -20.0, 10.0));
        // A fourth view whose source sits inside the batch: some vertices lie behind it.
        let mut behind = cams[0].clone();
        behind.t.z = -behind
            .r
            .transform_vector(&nalgebra::Vector3::new(30.0, -20.0, 10.0))
            .z;
        cams.push(behind);
        let rows: Vec<cproject::ViewRows> =
            cams.iter().map(cproject::ViewRows::from_camera).collect();
        let cpu = cproject::project(&verts, n, &rows);
        let g = gpu.project(&verts, n, &rows).unwrap();
        assert!(cpu.iter().any(|p| p[3] == 0.0) && cpu.iter().any(|p| p[3] == 1.0));
        project_ok(&cpu, &g).unwrap();
        let mut wrong = g.clone();
        wrong[77][0] += 0.05;
        assert!(project_ok(&cpu, &wrong).is_err());
    });
}

#[test]
fn silhouette_edges_match_the_twin_exactly_and_the_raster_within_a_stated_bound() {
    with_gpu(|gpu| {
        let mesh = hemisphere(26.0, 2500);
        let centre = Point3::new(0.0, 0.0, 0.0);
        for cam in simulated_views(&XrayGeometry::default(), &centre) {
            let (verts, tris) = mesh_buffers(&mesh);
            let view = cproject::ViewRows::from_camera(&cam);
            let s = gpu.silhouette(&verts, &tris, &view, 256).unwrap();
            // The edge kernel: exactly its twin run on the GPU's id image.
            let twin_mask = csil::edges(&s.ids, s.window.size);
            assert_eq!(s.mask, twin_mask, "edge kernel differs from its twin");
            let mut wrong = s.mask.clone();
            let k = wrong.iter().position(|&m| m == 0).unwrap();
            wrong[k] = 1;
            assert_ne!(
                wrong, twin_mask,
                "the comparison must reject a changed texel"
            );
            // The render pass against the CPU rasteriser: coverage may differ only where a
            // triangle edge passes through a texel centre's rounding; bound: 0.5 % of the
            // covered texels, and the same texel set on the silhouette within one texel.
            let proj = cproject::project(&verts, verts.len(), &[view]);
            let cpu_ids = csil::rasterise(&proj, &tris, &s.window);
            let covered = cpu_ids.iter().filter(|&&v| v != 0).count();
            let differ = cpu_ids
                .iter()
                .zip(&s.ids)
                .filter(|(a, b)| (**a != 0) != (**b != 0))
                .count();
            assert!(covered > 1000);
            assert!(
                differ * 200 <= covered,
                "coverage differs on {differ} of {covered} texels"
            );
            // The traced contour: a closed loop of rim-side vertex ids, most of the outline.
            assert!(s.contour.len() > 40, "contour of {} ids", s.contour.len());
            let cpu_loop = csil::trace(&csil::edges(&cpu_ids, s.window.size), s.window.size);
            let common = s.contour.iter().filter(|i| cpu_loop.contains(i)).count();
            assert!(
                common * 10 >= s.contour.len() * 9,
                "GPU and CPU loops share {common} of {}",
                s.contour.len()
            );
        }
    });
}

/// The silhouette's input is checked before anything is drawn: a triangle corner beyond the
/// vertices, corners that are not whole triangles and a texture larger than the device allows
/// are each an error naming what is wrong; the same mesh as given draws (the companion).
#[test]
fn the_silhouette_refuses_triangles_without_vertices_and_a_texture_too_large() {
    with_gpu(|gpu| {
        let mesh = hemisphere(26.0, 400);
        let centre = Point3::new(0.0, 0.0, 0.0);
        let cam = &simulated_views(&XrayGeometry::default(), &centre)[0];
        let (verts, tris) = mesh_buffers(&mesh);
        let view = cproject::ViewRows::from_camera(cam);
        let s = gpu.silhouette(&verts, &tris, &view, 128).unwrap();
        assert!(!s.contour.is_empty());
        let message = |r: Result<_, acetab::engine::gpu::GpuError>| r.err().map(|e| e.to_string());
        let mut beyond = tris.clone();
        beyond[4] = verts.len() as u32;
        let e = message(gpu.silhouette(&verts, &beyond, &view, 128)).expect("refused");
        assert!(
            e.contains(&format!(
                "triangle corner {} is not one of the",
                verts.len()
            )),
            "{e}"
        );
        let e =
            message(gpu.silhouette(&verts, &tris[..tris.len() - 1], &view, 128)).expect("refused");
        assert!(e.contains("is not a positive multiple of 3"), "{e}");
        let e = message(gpu.silhouette(&verts, &tris, &view, 1 << 20)).expect("refused");
        assert!(e.contains("texture size"), "{e}");
    });
}

fn wave(n: usize, f: f64, ph: f64) -> Vec<Vector2<f64>> {
    (0..n)
        .map(|i| {
            let t = i as f64 / (n - 1) as f64;
            Vector2::new((f * 5.0 * t + ph).cos(), (f * 3.0 * t).sin() + 0.2)
        })
        .collect()
}

#[test]
fn srvf_dp_back_pointers_equal_the_twin_exactly() {
    with_gpu(|gpu| {
        let steps = acetab::correspond::srvf::coprime_steps(5);
        type Owned = (Vec<Vector2<f64>>, Vec<Vector2<f64>>);
        let curves: Vec<Owned> = (0..17)
            .map(|k| {
                (
                    wave(64, 1.0 + 0.1 * k as f64, 0.0),
                    wave(64, 1.3 + 0.05 * k as f64, 0.2 * k as f64),
                )
            })
            .collect();
        let pairs: Vec<acetab::correspond::srvf::CurvePair<'_>> =
            curves.iter().map(|(a, b)| (&a[..], &b[..])).collect();
        let batch = cdp::DpBatch::new(&pairs, &steps).unwrap();
        let (cpu_cost, cpu_back) = cdp::dp_tables(&batch);
        let (gpu_cost, gpu_back) = gpu.srvf_dp_tables(&batch).unwrap();
        assert_eq!(gpu_back.len(), cpu_back.len());
        let differ = cpu_back
            .iter()
            .zip(&gpu_back)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(differ, 0, "{differ} back-pointers differ");
        // Costs: same operations in the same order; bound 1e-6 relative for the driver's
        // freedom to fuse multiply-adds.
        for (i, (a, b)) in cpu_cost.iter().zip(&gpu_cost).enumerate() {
            assert!(
                (a - b).abs() <= 1e-6 * a.abs().max(1.0),
                "cost {i}: {a} vs {b}"
            );
        }
        let mut wrong = gpu_back.clone();
        wrong[64 * 30 + 31] ^= 1;
        assert_ne!(
            wrong, cpu_back,
            "the comparison must reject one changed back-pointer"
        );
        // And the warps built from the GPU tables cost what the CPU's do.
        let wg = acetab::engine::cpu::srvf_dp::warps_from_tables(&pairs, &batch, &gpu_back);
        let wc = acetab::engine::cpu::srvf_dp::warps_from_tables(&pairs, &batch, &cpu_back);
        for (a, b) in wg.iter().zip(&wc) {
            assert_eq!(a.path, b.path);
        }
    });
}

#[test]
fn whole_reconstruction_on_the_gpu_matches_the_cpu() {
    with_gpu(|gpu| {
        use acetab::engine::Kernels;
        use acetab::pipeline::{reconstruct, ReconParams};
        use acetab::report::accuracy;

        use acetab::template::Template;
        let (truth, sim) = acetab::sim::phantom_case(3, 1).unwrap();
        let prm = ReconParams::default();
        let template = Template::standard();
        let input = sim.input(&template);
        let cpu = reconstruct(&input, &prm, Kernels::Cpu).unwrap();
        let gpu_r = reconstruct(&input, &prm, Kernels::Gpu(gpu)).unwrap();
        let (a, b) = (
            accuracy(&truth, &cpu.mesh).mae_mm,
            accuracy(&truth, &gpu_r.mesh).mae_mm,
        );
        eprintln!("MAE cpu {a:.4} gpu {b:.4} mm");
        assert!((a - b).abs() < 0.05, "MAE cpu {a} gpu {b}");
        assert!((cpu.sphere.diameter() - gpu_r.sphere.diameter()).abs() < 0.1);
        // Companion: a result 1 mm off everywhere must fail the same 0.05 mm bar.
        let shifted = gpu_r.mesh.transformed(
            1.0,
            &nalgebra::Rotation3::identity(),
            &nalgebra::Vector3::new(1.0, 0.0, 0.0),
        );
        let c = accuracy(&truth, &shifted).mae_mm;
        assert!((a - c).abs() >= 0.05, "a shifted mesh passed: {a} vs {c}");
        // Stricter than the MAE bar (which a 0.3 mm shift slips under): vertex by
        // vertex, the GPU result is the CPU's within 1e-3 mm; the shifted mesh is not.
        let worst = |m: &acetab::geom::Mesh| {
            cpu.mesh
                .vertices
                .iter()
                .zip(&m.vertices)
                .map(|(p, q)| (p - q).norm())
                .fold(0.0, f64::max)
        };
        assert!(
            worst(&gpu_r.mesh) < 1e-3,
            "vertices differ by {} mm",
            worst(&gpu_r.mesh)
        );
        assert!(worst(&shifted) >= 1e-3);
    });
}

#[test]
fn study_runs_batched_on_the_gpu_match_the_cpu() {
    with_gpu(|gpu| {
        use acetab::engine::gpu::GpuBatcher;
        use acetab::engine::Kernels;
        use acetab::sim::{phantom, PhantomParams};
        use acetab::study::{run_study, StudyConfig};
        let truth = phantom(&PhantomParams::default()).mesh;
        let cfg = StudyConfig {
            levels: vec![1],
            runs: 3,
            methods: vec![acetab::study::StudyMethod::Srvf],
            threads: 2,
            ..Default::default()
        };
        let batcher = GpuBatcher::new(gpu, 2, std::time::Duration::from_millis(5));
        let (cpu, _) = run_study(&truth, &cfg, &|| {}, Kernels::Cpu).unwrap();
        let (single, _) = run_study(&truth, &cfg, &|| {}, Kernels::Gpu(gpu)).unwrap();
        let (batched, _) = run_study(&truth, &cfg, &|| {}, Kernels::Batched(&batcher)).unwrap();
        let (req, disp) = batcher.counts();
        eprintln!("{req} requests in {disp} dispatches");
        // The per-kernel figures (summary.json's engine.kernels) add up to the totals.
        let st = batcher.stats();
        assert_eq!(st.deform.requests + st.project.requests, req);
        assert_eq!(st.deform.dispatches + st.project.dispatches, disp);
        assert!(disp > 0 && st.deform.device_seconds > 0.0, "{st:?}");
        for ((c, s), b) in cpu.iter().zip(&single).zip(&batched) {
            eprintln!(
                "run {}: cpu {} gpu {} batched {}",
                c.run, c.mae_mm, s.mae_mm, b.mae_mm
            );
            assert!((c.mae_mm - s.mae_mm).abs() < 0.05 && (s.mae_mm - b.mae_mm).abs() < 1e-12);
        }
        // Companion: the batched-vs-single check (1e-12) rejects a result 1e-9 mm away.
        let nudged = batched[0].mae_mm + 1e-9;
        assert!((single[0].mae_mm - nudged).abs() >= 1e-12);
        // The SRVF DPs on the device too (`--dp device`): every DP a request to the
        // srvf_band kernel, the runs' requests merged; the results the CPU's within the
        // issue's bars (MAE 0.05 mm, cup 0.1 mm).
        let on_device =
            GpuBatcher::new(gpu, 2, std::time::Duration::from_millis(5)).with_dp_on_device(true);
        let (dev, _) = run_study(&truth, &cfg, &|| {}, Kernels::Batched(&on_device)).unwrap();
        let st = on_device.stats();
        eprintln!("device DP: {:?}", st.srvf_band);
        assert!(
            st.srvf_band.requests > 0 && st.srvf_band.dispatches > 0,
            "{st:?}"
        );
        assert_eq!(st.srvf_band_on_host, 0, "every DP ran on the device");
        let agrees = |c: &acetab::study::Row, d: &acetab::study::Row| {
            (c.mae_mm - d.mae_mm).abs() < 0.05
                && (c.cup_diameter_mm - d.cup_diameter_mm).abs() < 0.1
        };
        for (c, d) in cpu.iter().zip(&dev) {
            eprintln!(
                "run {}: cpu {} / {} device DP {} / {}",
                c.run, c.mae_mm, c.cup_diameter_mm, d.mae_mm, d.cup_diameter_mm
            );
            assert!(d.error.is_empty() && agrees(c, d));
        }
        // Companion: a run whose cup is 0.2 mm off fails the same check.
        let mut off = dev[0].clone();
        off.cup_diameter_mm += 0.2;
        assert!(!agrees(&cpu[0], &off));
    });
}

/// One deform batch per test graph, and each one's output dispatched alone.
#[allow(clippy::type_complexity)]
fn deform_one_by_one(gpu: &Gpu) -> (Vec<cdeform::DeformBatch>, Vec<Vec<[f32; 4]>>) {
    let batches: Vec<cdeform::DeformBatch> = graphs()
        .iter()
        .map(|(g, x)| cdeform::DeformBatch::from_graphs(&[(g, &x[..])]).unwrap())
        .collect();
    let alone = batches.iter().map(|b| gpu.deform(b).unwrap()).collect();
    (batches, alone)
}

#[test]
fn the_batcher_merges_concurrent_requests_into_one_dispatch_with_exact_results() {
    with_gpu(|gpu| {
        use acetab::engine::gpu::GpuBatcher;
        let (batches, alone) = deform_one_by_one(gpu);
        let batcher = GpuBatcher::new(gpu, batches.len(), std::time::Duration::from_secs(5));
        let barrier = std::sync::Barrier::new(batches.len());
        let merged: Vec<Vec<[f32; 4]>> = std::thread::scope(|s| {
            let hs: Vec<_> = batches
                .iter()
                .map(|b| {
                    let (batcher, barrier) = (&batcher, &barrier);
                    s.spawn(move || {
                        barrier.wait();
                        batcher.deform(b.clone()).unwrap()
                    })
                })
                .collect();
            hs.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(
            batcher.counts(),
            (batches.len(), 1),
            "one dispatch for all runs"
        );
        assert_eq!(merged, alone, "each run gets exactly its own slice");
        // Companion: swapping two runs' slices is caught by the same comparison.
        let mut swapped = merged.clone();
        swapped.swap(0, 1);
        assert_ne!(swapped, alone);
    });
}

#[test]
fn acetab_bench_prints_its_table_as_json() {
    if device().is_none() {
        return;
    }
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_acetab"))
        .args([
            "bench",
            "--json",
            "--quick",
            "--study-runs",
            "2",
            "--repeats",
            "1",
            "--dp",
            "both",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let kernels: Vec<&str> = v["kernels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["kernel"].as_str().unwrap())
        .collect();
    for k in ["deform", "project", "silhouette", "srvf_dp", "srvf_band"] {
        assert!(kernels.contains(&k), "{k} missing from {kernels:?}");
    }
    for r in v["kernels"].as_array().unwrap() {
        for f in ["cpu_ms", "gpu_ms", "ratio"] {
            assert!(
                r[f].as_f64().is_some_and(|x| x.is_finite() && x > 0.0),
                "{r}"
            );
        }
    }
    let study = v["study"].as_array().unwrap();
    // cpu and gpu at --threads, then per batch size (--quick: 1 and 2) cpu, batched gpu and
    // batched gpu with the DPs on the device.
    assert_eq!(study.len(), 8, "{study:?}");
    let batches: Vec<(String, u64)> = study
        .iter()
        .map(|s| {
            (
                s["backend"].as_str().unwrap().to_string(),
                s["batch"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(batches[2], ("cpu".to_string(), 1));
    assert_eq!(batches[6], ("gpu, runs batched".to_string(), 2));
    assert_eq!(
        batches[7],
        ("gpu, runs batched, DP on the device".to_string(), 2)
    );
    assert!(study
        .iter()
        .all(|s| s["runs"] == 2 && s["runs_per_second"].as_f64().unwrap() > 0.0));
}

/// (coverage IoU, mean absolute channel difference where both are covered) of two panels.
fn panel_agreement(a: &[[u8; 4]], b: &[[u8; 4]]) -> (f64, f64) {
    let covered = |p: &[u8; 4]| p[..3] != [255, 255, 255];
    let (mut both, mut either, mut diff) = (0usize, 0usize, 0.0f64);
    for (p, q) in a.iter().zip(b) {
        match (covered(p), covered(q)) {
            (true, true) => {
                both += 1;
                either += 1;
                diff += (0..3)
                    .map(|c| (p[c] as f64 - q[c] as f64).abs())
                    .sum::<f64>()
                    / 3.0;
            }
            (false, false) => {}
            _ => either += 1,
        }
    }
    (
        both as f64 / either.max(1) as f64,
        diff / both.max(1) as f64,
    )
}

#[test]
fn the_surface_picture_on_the_gpu_matches_its_cpu_twin() {
    with_gpu(|gpu| {
        use acetab::engine::cpu::surface::{render_surface, SurfaceView};
        use acetab::sim::{phantom, PhantomParams};
        let ph = phantom(&PhantomParams::default());
        let mesh = &ph.mesh;
        let (points, tris) = mesh_buffers(mesh);
        // Colours that vary over the surface, so interpolation and shading both show.
        let colors: Vec<[f32; 4]> = (0..points.len())
            .map(|i| [(i % 7) as f32 / 7.0, 0.3, 1.0 - (i % 5) as f32 / 5.0, 1.0])
            .collect();
        let c = ph.placement.center;
        let look = -ph.placement.axis.into_inner();
        let view = |look: &nalgebra::Vector3<f64>| {
            SurfaceView::looking(&c, look, &nalgebra::Vector3::z(), 6.0, 40.0, 400)
        };
        let cpu = render_surface(&points, &colors, &tris, &view(&look));
        let on_gpu = gpu
            .render_surface(&points, &colors, &tris, &view(&look))
            .unwrap();
        let (iou, diff) = panel_agreement(&cpu, &on_gpu);
        eprintln!("surface panel: coverage IoU {iou:.4}, mean channel difference {diff:.2}");
        assert!(iou > 0.98 && diff < 4.0, "IoU {iou}, difference {diff}");
        // Companion: the surface seen 10 degrees off is told apart by the same check.
        let turned =
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), 0.17) * look;
        let off = gpu
            .render_surface(&points, &colors, &tris, &view(&turned))
            .unwrap();
        let (iou2, diff2) = panel_agreement(&cpu, &off);
        assert!(
            !(iou2 > 0.98 && diff2 < 4.0),
            "IoU {iou2}, difference {diff2}"
        );
        // Bad input is an error, not a picture.
        assert!(gpu
            .render_surface(&points, &colors[1..], &tris, &view(&look))
            .is_err());
        assert!(gpu
            .render_surface(&points, &colors, &[0, 1, 99_999], &view(&look))
            .is_err());
    });
}

/// q1, q2, the band's first and last columns per row, the position weight.
type BandCase = (
    Vec<Vector2<f64>>,
    Vec<Vector2<f64>>,
    Vec<usize>,
    Vec<usize>,
    f64,
);

/// Banded DP problems as alignments pose them: curves of several lengths, bands around a
/// wandering path of several widths and the full feasible band, with and without the position
/// term.
fn band_problems() -> Vec<BandCase> {
    let mut out = Vec::new();
    for (k, &(n, half, weight)) in [
        (40usize, 40usize, 0.0),
        (64, 5, 3.0),
        (101, 6, 3.0),
        (200, 6, 3.0),
        (200, 9, 0.0),
    ]
    .iter()
    .enumerate()
    {
        let q1 = wave(n, 1.0 + 0.1 * k as f64, 0.0);
        let q2 = wave(n, 1.2 + 0.07 * k as f64, 0.3 * k as f64);
        // Around j = i + 3 sin(...), clamped to the grid; row 0 only the start.
        let (mut lo, mut hi) = (vec![0usize; n], vec![0usize; n]);
        for i in 1..n {
            let c = i as f64 + 3.0 * (i as f64 / 17.0).sin();
            lo[i] = ((c - half as f64).floor().max(1.0) as usize).min(n - 1);
            hi[i] = ((c + half as f64).ceil() as usize).clamp(lo[i], n - 1);
        }
        hi[n - 1] = n - 1;
        out.push((q1, q2, lo, hi, weight));
    }
    out
}

#[test]
fn srvf_band_back_pointers_equal_the_twin_exactly() {
    use acetab::correspond::srvf::{coprime_steps, Anchor, BandProblem};
    use acetab::engine::cpu::srvf_band as cband;
    with_gpu(|gpu| {
        let steps = coprime_steps(5);
        let owned = band_problems();
        let problems: Vec<BandProblem> = owned
            .iter()
            .map(|(q1, q2, lo, hi, w)| BandProblem {
                q1,
                q2,
                steps: &steps,
                lo,
                hi,
                // The SRVFs themselves stand in for the positions.
                anchor: Some(Anchor {
                    a: q2,
                    b: q1,
                    weight: *w,
                }),
            })
            .collect();
        let batch = cband::BandBatch::new(&problems).unwrap();
        let (cpu_cost, cpu_back) = cband::band_tables(&batch);
        let (gpu_cost, gpu_back) = gpu.srvf_band_tables(&batch).unwrap();
        assert_eq!(gpu_back.len(), batch.cells);
        let differ = cpu_back
            .iter()
            .zip(&gpu_back)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(
            differ, 0,
            "{differ} of {} back-pointers differ",
            batch.cells
        );
        for (i, (a, b)) in cpu_cost.iter().zip(&gpu_cost).enumerate() {
            assert!(
                (a - b).abs() <= 1e-6 * a.abs().max(1.0),
                "cost {i}: {a} vs {b}"
            );
        }
        // Every problem's band holds a path (the tables are not all unreached).
        for (k, p) in problems.iter().enumerate() {
            let back = batch.slice(&gpu_back, k);
            assert!(
                acetab::correspond::srvf::trace_band(back, p.lo, p.hi, &steps).is_some(),
                "problem {k}: no path"
            );
        }
        // Companion: one back-pointer changed is told apart.
        let mut wrong = gpu_back.clone();
        wrong[batch.cells / 2] ^= 1;
        assert_ne!(
            wrong, cpu_back,
            "the comparison must reject one changed back-pointer"
        );
    });
}

/// A band solver that runs the GPU's DP and then points every cell at the diagonal step, so
/// that every warp comes out straight: a wrong answer the alignment comparison must reject.
struct Corrupted<'a>(&'a Gpu<'a>);

impl acetab::correspond::srvf::BandSolver for Corrupted<'_> {
    fn back_pointers(&self, p: &acetab::correspond::srvf::BandProblem) -> Option<Vec<u32>> {
        let back = self.0.back_pointers(p)?;
        let diagonal = p.steps.iter().position(|&s| s == (1, 1))? as u32;
        Some(vec![diagonal; back.len()])
    }
}

#[test]
fn alignments_with_their_dps_on_the_gpu_equal_the_hosts() {
    use acetab::correspond::srvf::{align, align_on, CurveKind, DpOn, SrvfParams};
    use nalgebra::Point2;
    with_gpu(|gpu| {
        // A dented, noisy closed outline against a smooth ellipse, an open arc against it, and
        // the study's settings (bounded rotation, position term).
        let outline: Vec<Point2<f64>> = (0..28)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 28.0;
                let bump = 1.0 + 0.35 * (-((t - 1.2) / 0.4).powi(2)).exp();
                let dent = if (4.0..4.5).contains(&t) { 0.8 } else { 1.0 };
                let jitter = 0.3 * ((i * 7919) % 13) as f64 / 13.0;
                let r = bump * dent;
                Point2::new(r * 30.0 * t.cos() + jitter, r * 22.0 * t.sin() - jitter)
            })
            .collect();
        let model: Vec<Point2<f64>> = (0..140)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 140.0 + 0.1;
                Point2::new(29.0 * t.cos() + 0.5, 23.0 * t.sin())
            })
            .collect();
        let prm = acetab::correspond::CorrespondParams::default().srvf;
        let coarse = SrvfParams {
            samples: 100,
            ..prm.clone()
        };
        let arc = &outline[3..20];
        let cases = [
            (&outline[..], CurveKind::Closed, &prm),
            (&outline[..], CurveKind::Closed, &coarse),
            (arc, CurveKind::Partial, &prm),
        ];
        let same = |x: &acetab::correspond::srvf::Alignment,
                    y: &acetab::correspond::srvf::Alignment| {
            x.seed == y.seed && x.gamma == y.gamma && x.rotation == y.rotation
        };
        for (k, (a, kind, p)) in cases.iter().enumerate() {
            let host = align(a, &model, *kind, p).unwrap();
            // The warp is not the straight one (the corrupted solver's), or the companion
            // below would prove nothing.
            let t = host.gamma.len();
            let bend = host
                .gamma
                .iter()
                .enumerate()
                .map(|(i, g)| (g - i as f64 / (t - 1) as f64).abs())
                .fold(0.0, f64::max);
            assert!(bend > 0.01, "case {k}: a straight warp ({bend})");
            let dev = align_on(a, &model, *kind, p, DpOn::Device(gpu)).unwrap();
            assert!(
                same(&host, &dev),
                "case {k}: the device's alignment differs"
            );
            // Companion: wrong back-pointers give an alignment the same check rejects.
            let bad = Corrupted(gpu);
            let wrong = align_on(a, &model, *kind, p, DpOn::Device(&bad)).unwrap();
            assert!(!same(&host, &wrong), "case {k}: corrupted tables passed");
        }
    });
}

#[test]
fn registered_runs_go_to_the_device_in_lock_step() {
    with_gpu(|gpu| {
        use acetab::engine::gpu::GpuBatcher;
        use std::time::{Duration, Instant};
        let (batches, alone) = deform_one_by_one(gpu);
        // Three runs reach the device 0, 30 and 60 ms apart (host work of different lengths);
        // `lanes` above their number and a 5 s wait, so only the lock-step rule can send them.
        let staggered = |batcher: &GpuBatcher, register: bool| {
            let start = Instant::now();
            // Every run registers before any starts: a run that reached the device before the
            // others had registered would be sent alone (a race the loaded CI machine lost).
            let guards: Vec<_> = batches
                .iter()
                .map(|_| register.then(|| batcher.run()))
                .collect();
            let out: Vec<Vec<[f32; 4]>> = std::thread::scope(|s| {
                let hs: Vec<_> = batches
                    .iter()
                    .zip(guards)
                    .enumerate()
                    .map(|(k, (b, guard))| {
                        s.spawn(move || {
                            let _guard = guard;
                            std::thread::sleep(Duration::from_millis(30 * k as u64));
                            batcher.deform(b.clone()).unwrap()
                        })
                    })
                    .collect();
                hs.into_iter().map(|h| h.join().unwrap()).collect()
            });
            (out, start.elapsed())
        };
        let locked = GpuBatcher::new(gpu, 10, Duration::from_secs(5));
        let (out, took) = staggered(&locked, true);
        assert_eq!(out, alone, "each run gets exactly its own slice");
        assert_eq!(
            locked.counts(),
            (batches.len(), 1),
            "one dispatch for the step"
        );
        assert!(
            took < Duration::from_secs(2),
            "sent when all waited: {took:?}"
        );
        // Companion: the same runs unregistered, with a short wait, are not sent together.
        let free = GpuBatcher::new(gpu, 10, Duration::from_millis(5));
        let (out, _) = staggered(&free, false);
        assert_eq!(out, alone);
        assert!(free.counts().1 > 1, "{:?}", free.counts());
    });
}
