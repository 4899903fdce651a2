//! One whole reconstruction of the phantom (level 3, seed 1), SRVF correspondences.

use acetab::engine::Kernels;
use acetab::pipeline::{reconstruct, ReconParams};
use acetab::template::Template;
use criterion::{criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let (_truth, sim) = acetab::sim::phantom_case(3, 1).unwrap();
    let prm = ReconParams::default();
    let template = Template::standard();
    let mut g = c.benchmark_group("reconstruct");
    g.sample_size(10);
    g.bench_function("phantom_level3", |b| {
        b.iter(|| reconstruct(&sim.input(&template), &prm, Kernels::Cpu).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
