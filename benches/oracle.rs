//! Cost of the clairvoyant oracle (`sim::oracle::solve`): time to solve one 50-step episode,
//! per variant, on random (A) and seasonal (B) input. The cost depends on the variant and the
//! episode length, not on the input: the basic line has 10 states a step, the advanced one up
//! to 10 (t + 1). Each iteration solves a fresh seed, as `sorting_line oracle` and `eval` do.
//!
//! Run: `cargo bench --bench oracle` (about 20 s).

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion};
use sorting_line::sim::oracle::solve;
use sorting_line::sim::{LineConfig, Setup, Variant};

fn main() {
    let mut c = Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .sample_size(30)
        .configure_from_args();
    let mut group = c.benchmark_group("oracle");
    for variant in [Variant::Basic, Variant::Advanced] {
        for setup in [Setup::A, Setup::B] {
            let config = LineConfig::for_setup(setup, variant);
            let mut seed = 42;
            group.bench_function(BenchmarkId::new(variant.to_string(), format!("{setup:?}")), |b| {
                b.iter(|| {
                    seed += 1;
                    black_box(solve(&config, seed).unwrap().reward)
                })
            });
        }
    }
    group.finish();
    c.final_summary();
}
