//! SRVF alignment speed: closed and open curves at T = 100, 200, 400.

use acetab::correspond::srvf::{align_closed, align_open, align_partial, SrvfParams};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::Point2;

fn blob(n: usize, stretch: f64) -> Vec<Point2<f64>> {
    (0..n)
        .map(|i| {
            let t = std::f64::consts::TAU * i as f64 / n as f64;
            let r = 1.0 + 0.3 * (2.0 * t).cos() + 0.15 * (3.0 * t + 0.4).sin();
            Point2::new(stretch * r * t.cos(), 0.8 * r * t.sin())
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let a = blob(400, 1.0);
    let b: Vec<Point2<f64>> = blob(350, 1.1)
        .into_iter()
        .cycle()
        .skip(90)
        .take(350)
        .collect();
    let mut g = c.benchmark_group("srvf");
    g.sample_size(10);
    for t in [100usize, 200, 400] {
        let prm = SrvfParams {
            samples: t,
            ..Default::default()
        };
        g.bench_with_input(BenchmarkId::new("closed", t), &prm, |bch, prm| {
            bch.iter(|| align_closed(&a, &b, prm, false).unwrap())
        });
        let (ao, bo) = (&a[..250], &b[..220]);
        g.bench_with_input(BenchmarkId::new("open", t), &prm, |bch, prm| {
            bch.iter(|| align_open(ao, bo, prm).unwrap())
        });
        // Partial: an open arc (a third of A, from a differently shaped copy) against closed A.
        let arc = &b[40..160];
        g.bench_with_input(BenchmarkId::new("partial", t), &prm, |bch, prm| {
            bch.iter(|| align_partial(arc, &a, prm).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
