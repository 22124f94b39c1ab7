//! Speed of the simulation and of the rule-based agent (criterion), then a summary of the
//! figures against the project's targets and the reference implementation.
//!
//! - `steps/<variant>/<input>`: steps per second of one line (one core), with a cheap scripted
//!   action sequence and a reset every 50 steps, as an evaluation or a training loop runs it.
//! - `rba/<decide|decide_holding>/<variant>`: time of one decision of a built table, over
//!   precomputed noisy observations (the table's construction is a one-off and not measured).
//!
//! Targets: at least 4,000,000 steps/s per core (100x the reference's pure-Python 44k basic /
//! 38k advanced) and under 1 microsecond per decision (reference: 0.08 ms basic, 0.69 ms
//! advanced). The summary reads criterion's median estimates from
//! `<criterion dir>/<group>/<function>/<value>/new/estimates.json`, written by this very run.
//!
//! Run: `cargo bench --bench sim` (about 40 s).

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use criterion::{BenchmarkId, Criterion, Throughput};
use sorting_line::sim::rba::RbaTable;
use sorting_line::sim::{Action, Line, LineConfig, Observation, Setup, SortMode, Variant};

/// Steps per measured iteration: twenty 50-step episodes.
const STEPS_PER_ITER: u64 = 1000;
const EPISODE_STEPS: u64 = 50;
/// Decisions per measured iteration.
const DECISIONS_PER_ITER: usize = 1024;

const TARGET_STEPS_PER_S: f64 = 4_000_000.0;
const TARGET_NS_PER_DECISION: f64 = 1000.0;

/// What a benchmark's figure means and what it is held against.
#[derive(Clone, Copy)]
enum Measure {
    /// Steps per second; the reference's steps per second.
    Steps { reference: f64 },
    /// Nanoseconds per decision; the reference's nanoseconds per decision.
    Decision { reference_ns: f64 },
}

/// One registered benchmark, for the summary.
struct Entry {
    group: &'static str,
    function: &'static str,
    value: &'static str,
    /// Work items per criterion iteration (steps or decisions).
    per_iter: u64,
    measure: Measure,
}

fn variant_name(variant: Variant) -> &'static str {
    match variant {
        Variant::Basic => "basic",
        Variant::Advanced => "advanced",
    }
}

/// Every (speed, mode) pair in turn: changes speed every step, so the penalty path runs too.
fn scripted_actions() -> Vec<Action> {
    (0..30).map(|k| Action::new(k % 10, SortMode::from_index((k % 3) as u8).unwrap())).collect()
}

fn run_steps(line: &mut Line, actions: &[Action], steps: u64) -> f64 {
    let mut reward = 0.0;
    for (k, action) in (0..steps).zip(actions.iter().cycle()) {
        if k % EPISODE_STEPS == 0 {
            line.reset(None);
        }
        reward += line.step(*action).reward;
    }
    reward
}

fn bench_steps(c: &mut Criterion) -> Vec<Entry> {
    let actions = scripted_actions();
    let mut group = c.benchmark_group("steps");
    group.throughput(Throughput::Elements(STEPS_PER_ITER));
    let mut entries = Vec::new();
    // Setups A and B: random and seasonal input (the sensor noise costs the same draw either way).
    for variant in [Variant::Basic, Variant::Advanced] {
        for (setup, input) in [(Setup::A, "random"), (Setup::B, "seasonal")] {
            let mut line = Line::new(LineConfig::for_setup(setup, variant), 42);
            let function = variant_name(variant);
            group.bench_function(BenchmarkId::new(function, input), |b| {
                b.iter(|| black_box(run_steps(&mut line, &actions, STEPS_PER_ITER)))
            });
            let reference = if variant == Variant::Basic { 44_000.0 } else { 38_000.0 };
            entries.push(Entry {
                group: "steps",
                function,
                value: input,
                per_iter: STEPS_PER_ITER,
                measure: Measure::Steps { reference },
            });
        }
    }
    group.finish();
    entries
}

/// Observations as the agent meets them: noisy readings of seasonal input (setup D).
fn observations(variant: Variant) -> Vec<Observation> {
    let mut line = Line::new(LineConfig::for_setup(Setup::D, variant), 7);
    let actions = scripted_actions();
    (0..DECISIONS_PER_ITER).map(|k| line.step(actions[k % actions.len()]).observation).collect()
}

fn bench_rba(c: &mut Criterion) -> Vec<Entry> {
    let mut group = c.benchmark_group("rba");
    group.throughput(Throughput::Elements(DECISIONS_PER_ITER as u64));
    let mut entries = Vec::new();
    for variant in [Variant::Basic, Variant::Advanced] {
        let table = RbaTable::build(&LineConfig::for_setup(Setup::D, variant));
        let observations = observations(variant);
        let speeds: Vec<usize> = (0..DECISIONS_PER_ITER).map(|k| (k * 7) % 10).collect();
        let name = variant_name(variant);
        group.bench_function(BenchmarkId::new("decide", name), |b| {
            b.iter(|| observations.iter().map(|&o| table.decide(black_box(o)).speed_index).sum::<usize>())
        });
        group.bench_function(BenchmarkId::new("decide_holding", name), |b| {
            b.iter(|| {
                observations
                    .iter()
                    .zip(&speeds)
                    .map(|(&o, &s)| table.decide_holding(black_box(o), black_box(s)).speed_index)
                    .sum::<usize>()
            })
        });
        // The reference has no holding agent: both are held against its plain RBA.
        let reference_ns = if variant == Variant::Basic { 80_000.0 } else { 690_000.0 };
        for function in ["decide", "decide_holding"] {
            entries.push(Entry {
                group: "rba",
                function,
                value: name,
                per_iter: DECISIONS_PER_ITER as u64,
                measure: Measure::Decision { reference_ns },
            });
        }
    }
    group.finish();
    entries
}

/// Where criterion writes its results: as criterion's default ($CRITERION_HOME, else
/// $CARGO_TARGET_DIR/criterion), else `criterion` beside the profile directory this bench runs
/// from (target/release/deps/sim-* -> target/criterion). Set explicitly so the summary reads
/// exactly what criterion wrote.
fn criterion_dir() -> PathBuf {
    if let Some(home) = std::env::var_os("CRITERION_HOME") {
        return home.into();
    }
    if let Some(target) = std::env::var_os("CARGO_TARGET_DIR") {
        return PathBuf::from(target).join("criterion");
    }
    std::env::current_exe()
        .ok()
        .and_then(|exe| exe.ancestors().nth(3).map(|target| target.join("criterion")))
        .unwrap_or_else(|| PathBuf::from("target/criterion"))
}

/// The median time of one iteration in ns, if this run (started at `since`) measured it.
fn median_ns(dir: &Path, entry: &Entry, since: SystemTime) -> Option<f64> {
    let path = dir.join(entry.group).join(entry.function).join(entry.value).join("new/estimates.json");
    let fresh = std::fs::metadata(&path).and_then(|m| m.modified()).is_ok_and(|t| t >= since);
    if !fresh {
        return None; // not run this time (filtered out, or criterion's --test / --list mode)
    }
    let estimates: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).ok()?).ok()?;
    estimates["median"]["point_estimate"].as_f64()
}

/// `12345678.9` -> `12,345,679`.
fn thousands(x: f64) -> String {
    let digits = format!("{:.0}", x);
    let mut out = String::new();
    for (i, ch) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(ch);
    }
    out
}

fn print_summary(entries: &[Entry], dir: &Path, since: SystemTime) {
    let rows: Vec<[String; 7]> = entries
        .iter()
        .filter_map(|e| {
            let ns_per_item = median_ns(dir, e, since)? / e.per_iter as f64;
            let id = format!("{}/{}/{}", e.group, e.function, e.value);
            // Both ratios read "times better": above 1 beats the target or the reference.
            Some(match e.measure {
                Measure::Steps { reference } => {
                    let per_s = 1e9 / ns_per_item;
                    [
                        id,
                        format!("{} steps/s", thousands(per_s)),
                        format!(">= {} steps/s", thousands(TARGET_STEPS_PER_S)),
                        format!("{:.2}x", per_s / TARGET_STEPS_PER_S),
                        if per_s >= TARGET_STEPS_PER_S { "yes" } else { "NO" }.into(),
                        format!("{} steps/s", thousands(reference)),
                        format!("{:.0}x", per_s / reference),
                    ]
                }
                Measure::Decision { reference_ns } => [
                    id,
                    format!("{ns_per_item:.2} ns/decision"),
                    format!("< {} ns", thousands(TARGET_NS_PER_DECISION)),
                    format!("{:.0}x", TARGET_NS_PER_DECISION / ns_per_item),
                    if ns_per_item < TARGET_NS_PER_DECISION { "yes" } else { "NO" }.into(),
                    format!("{} ns", thousands(reference_ns)),
                    format!("{:.0}x", reference_ns / ns_per_item),
                ],
            })
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    let header =
        ["benchmark", "measured (median)", "target", "vs target", "met", "reference", "vs reference"].map(String::from);
    let widths: Vec<usize> =
        (0..header.len()).map(|i| rows.iter().chain([&header]).map(|r| r[i].len()).max().unwrap()).collect();
    let line = |r: &[String; 7]| {
        let cells: Vec<String> = r.iter().zip(&widths).map(|(c, w)| format!("{c:<w$}")).collect();
        format!("| {} |", cells.join(" | "))
    };
    println!("\nSummary (one core; criterion medians from {}):", dir.display());
    println!("{}", line(&header));
    println!("|{}|", widths.iter().map(|w| "-".repeat(w + 2)).collect::<Vec<_>>().join("|"));
    for r in &rows {
        println!("{}", line(r));
    }
}

fn main() {
    let since = SystemTime::now();
    let dir = criterion_dir();
    // Short runs: 8 benchmarks x (1 s warm-up + 3 s measurement) keeps the whole bench near 40 s;
    // the per-iteration work is large enough (~0.1 ms) for stable medians at 30 samples.
    let mut c = Criterion::default()
        .output_directory(&dir)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .sample_size(30)
        .configure_from_args();
    let mut entries = bench_steps(&mut c);
    entries.extend(bench_rba(&mut c));
    c.final_summary();
    print_summary(&entries, &dir, since);
}
