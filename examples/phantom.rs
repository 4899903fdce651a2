//! Reconstruct the built-in phantom through the library API (what `acetab demo` does), printing
//! the accuracy and the cup size: `cargo run --release --example phantom -- [seed] [level]`.

use acetab::engine::Kernels;
use acetab::pipeline::ReconParams;
use acetab::sim::run_demo;

fn main() {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(1);
    let level: u32 = args.next().and_then(|s| s.parse().ok()).unwrap_or(3);
    match run_demo(seed, level, &ReconParams::default(), Kernels::Cpu) {
        Ok((r, _, rec)) => println!(
            "seed {seed} level {level}: MAE {:.3} mm, p95 {:.3} mm, cup {:.2} mm (truth {:.2}), catalogue {} mm, {:.1} s",
            r.mae_mm, r.p95_mm, r.cup_diameter_mm, r.gt_cup_diameter_mm, rec.cup.catalogue_mm, r.seconds
        ),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
