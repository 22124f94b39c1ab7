//! Golden trajectories: a few scripted runs of the line, recorded step by step in
//! `tests/data/golden/<case>.json` and compared *exactly* (floats with `==`).
//!
//! These pin the benchmark's definition: the random streams, the order of draws, the step order,
//! truncation and the reset semantics. Any change to them, even one ULP in a reward, fails here
//! with the case, the record and the field that moved. If the change is deliberate, re-record with
//!
//! ```text
//! SORTING_LINE_BLESS=1 cargo test --release --test golden
//! ```
//!
//! and review the diff of the JSON files. A missing file is a failure, never a silent pass.

use std::fmt::Write as _;
use std::fs;
use std::path::PathBuf;

use serde::Serialize;
use serde_json::{json, Value};
use sorting_line::sim::evolution::Schedule;
use sorting_line::sim::speed::OCCUPANCY_LIMITS;
use sorting_line::sim::{
    Action, Batch, Category, InputKind, Line, LineConfig, Observation, Setup, SortMode, StepOutcome, Variant,
};

const BLESS_VAR: &str = "SORTING_LINE_BLESS";
/// Steps per case: past the 50-step limit, because the line keeps stepping after truncation.
const STEPS: usize = 60;
/// Mismatches listed per case before the message is cut short.
const MAX_REPORTED: usize = 25;

/// One scripted run.
struct Case {
    name: &'static str,
    config: LineConfig,
    seed: u64,
    /// Reset after this many steps of the case, with this seed (`None`: streams carry on).
    reset: Option<(usize, Option<u64>)>,
    /// The action for step `k` of the case (0-based), given the last observation.
    policy: fn(usize, Observation) -> Action,
}

fn mode(i: usize) -> SortMode {
    SortMode::from_index((i % 3) as u8).expect("0..3 is a mode")
}

/// 0, 1, ..., 9, 8, ..., 1, 0, 1, ...: every speed, and every change of one notch both ways.
fn triangle(k: usize) -> usize {
    let p = k % 18;
    if p <= 9 {
        p
    } else {
        18 - p
    }
}

/// The fastest speed whose occupancy limit covers the reading: a plausible agent, so the
/// trajectories spend time in the accuracy regime that matters (near the threshold).
fn fitting_speed(quantity: f64) -> usize {
    (0..OCCUPANCY_LIMITS.len()).rev().find(|&i| OCCUPANCY_LIMITS[i] >= quantity).unwrap_or(0)
}

fn cases() -> Vec<Case> {
    let setup = LineConfig::for_setup;
    vec![
        Case {
            name: "basic_a_seed42",
            config: setup(Setup::A, Variant::Basic),
            seed: 42,
            reset: None,
            policy: |k, _| Action::new(triangle(k), SortMode::Basic),
        },
        Case {
            name: "basic_d_seed7",
            config: setup(Setup::D, Variant::Basic),
            seed: 7,
            reset: Some((52, None)),
            // Runs of four equal speeds: the penalty is charged on some steps and not on others.
            policy: |k, _| Action::new((k / 4 * 3) % 10, SortMode::Basic),
        },
        Case {
            name: "advanced_b_seed42",
            config: setup(Setup::B, Variant::Advanced),
            seed: 42,
            reset: None,
            // 10 speeds x 3 modes are coprime: every (speed, mode) pair within 30 steps.
            policy: |k, _| Action::new(k % 10, mode(k)),
        },
        Case {
            name: "advanced_c_seed3",
            config: setup(Setup::C, Variant::Advanced),
            seed: 3,
            reset: Some((52, Some(1234))),
            // Mostly the matching mode (two noise draws a step), every 7th step a mismatch.
            policy: |k, obs| {
                let matched = obs.category.index();
                Action::new(fitting_speed(obs.quantity), mode(if k % 7 == 0 { matched + 1 } else { matched }))
            },
        },
        Case {
            name: "advanced_seasonal3_seed11",
            config: LineConfig {
                variant: Variant::Advanced,
                input: InputKind::Seasonal3,
                obs_noise: 0.2,
                action_penalty: 0.3,
                ..LineConfig::default()
            },
            seed: 11,
            reset: None,
            policy: |k, obs| Action::new(fitting_speed(obs.quantity), mode(k / 5)),
        },
    ]
}

/// The state of the line after an event. Batches are `[a, b]`, containers
/// `[a, a_false, b, b_false]`: one line per record keeps the files small and diffs readable.
#[derive(Serialize)]
struct Record {
    /// `new`, `step`, `reset(None)` or `reset(Some(seed))`.
    event: String,
    episode: u32,
    step: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    reward: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    accuracy: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    occupancy: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    speed_changed: Option<bool>,
    truncated: bool,
    obs_quantity: f64,
    obs_category: Category,
    speed_index: usize,
    mode: SortMode,
    containers: [u64; 4],
    input: [u32; 2],
    belt: [u32; 2],
    machine: [u32; 2],
}

fn pair(batch: Batch) -> [u32; 2] {
    [batch.a, batch.b]
}

fn record(line: &Line, event: String, outcome: Option<&StepOutcome>) -> Record {
    let c = line.containers();
    let observation = line.observation();
    if let Some(out) = outcome {
        // The outcome and the line must tell the same story; the file records it once.
        assert_eq!(out.observation, observation);
        assert!(!out.terminated, "nothing but the time limit ends an episode");
    }
    Record {
        event,
        episode: line.episode(),
        step: line.step_count(),
        reward: outcome.map(|o| o.reward),
        accuracy: outcome.map(|o| o.accuracy),
        occupancy: outcome.map(|o| o.occupancy),
        speed_changed: outcome.map(|o| o.speed_changed),
        truncated: outcome.map_or(line.truncated(), |o| o.truncated),
        obs_quantity: observation.quantity,
        obs_category: observation.category,
        speed_index: line.speed_index(),
        mode: line.mode(),
        containers: [c.a, c.a_false, c.b, c.b_false],
        input: pair(line.input()),
        belt: pair(line.belt()),
        machine: pair(line.machine()),
    }
}

/// How a case's line is built: as a plain line, or as an evolving line with the empty schedule
/// (which must be the very same line).
type Build = fn(&Case) -> Line;

fn plain(case: &Case) -> Line {
    Line::new(case.config.clone(), case.seed)
}

fn empty_evolution(case: &Case) -> Line {
    let empty = Schedule::from_yaml("events: []\n").expect("the empty schedule");
    Line::with_evolution(case.config.clone(), case.seed, empty)
}

/// Runs a case.
fn run(case: &Case) -> Vec<Record> {
    run_built(case, plain)
}

fn run_built(case: &Case, build: Build) -> Vec<Record> {
    let mut line = build(case);
    let mut records = vec![record(&line, "new".into(), None)];
    for k in 0..STEPS {
        let out = line.step((case.policy)(k, line.observation()));
        records.push(record(&line, "step".into(), Some(&out)));
        if let Some((after, seed)) = case.reset {
            if after == k + 1 {
                line.reset(seed);
                records.push(record(&line, format!("reset({seed:?})"), None));
            }
        }
    }
    records
}

fn to_values(records: &[Record]) -> Vec<Value> {
    records.iter().map(|r| serde_json::to_value(r).expect("a record serialises")).collect()
}

/// Everything in a golden file except the records.
fn header(case: &Case) -> Value {
    json!({
        "case": case.name,
        "seed": case.seed,
        "config": case.config,
        "layout": "batches [a, b]; containers [a, a_false, b, b_false]; reward..speed_changed only on steps",
    })
}

fn golden_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/golden")
}

fn compact(value: &impl Serialize) -> String {
    serde_json::to_string(value).expect("records and JSON values serialise")
}

/// The header, then one record per line (fields in struct order, for the reader).
fn render(header: &Value, records: &[Record]) -> String {
    let mut text = String::from("{\n");
    for (key, value) in header.as_object().expect("the header is an object") {
        writeln!(text, "  {}: {},", compact(&json!(key)), compact(value)).unwrap();
    }
    text.push_str("  \"records\": [\n");
    for (i, r) in records.iter().enumerate() {
        let comma = if i + 1 < records.len() { "," } else { "" };
        writeln!(text, "    {}{comma}", compact(r)).unwrap();
    }
    text.push_str("  ]\n}\n");
    text
}

/// Every leaf where `expected` and `actual` differ, as (path, expected, actual). Numbers compare
/// exactly: with serde_json's `float_roundtrip` the file holds the very same f64.
fn differences(path: &str, expected: &Value, actual: &Value, out: &mut Vec<(String, String, String)>) {
    let show = |v: Option<&Value>| v.map_or("<absent>".to_string(), compact);
    match (expected, actual) {
        (Value::Object(e), Value::Object(a)) => {
            let mut keys: Vec<&String> = e.keys().chain(a.keys()).collect();
            keys.sort();
            keys.dedup();
            for key in keys {
                let sub = if path.is_empty() { key.clone() } else { format!("{path}.{key}") };
                match (e.get(key), a.get(key)) {
                    (Some(ev), Some(av)) => differences(&sub, ev, av, out),
                    (ev, av) => out.push((sub, show(ev), show(av))),
                }
            }
        }
        (Value::Array(e), Value::Array(a)) if e.len() == a.len() => {
            for (i, (ev, av)) in e.iter().zip(a).enumerate() {
                differences(&format!("{path}[{i}]"), ev, av, out);
            }
        }
        _ if expected != actual => out.push((path.to_string(), compact(expected), compact(actual))),
        _ => {}
    }
}

/// Where a record sits in the run, for messages: "record 17 (step, step 17 of episode 0)".
fn locate(index: usize, record: &Value) -> String {
    let event = record["event"].as_str().unwrap_or("?");
    format!("record {index} ({event}, step {} of episode {})", record["step"], record["episode"])
}

fn check(name: &str) {
    check_built(name, plain, true);
}

/// Compares a case's run with its golden file (`blessable`: a bless run may rewrite the file).
fn check_built(name: &str, build: Build, blessable: bool) {
    let case = cases().into_iter().find(|c| c.name == name).expect("a case of that name");
    let header = header(&case);
    let records = run_built(&case, build);
    let path = golden_dir().join(format!("{name}.json"));
    if blessable && std::env::var(BLESS_VAR).is_ok_and(|v| v == "1") {
        fs::create_dir_all(golden_dir()).expect("create tests/data/golden");
        fs::write(&path, render(&header, &records)).expect("write the golden file");
        eprintln!("blessed {}", path.display());
        return;
    }
    let text = fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!("golden case `{name}`: cannot read {} ({e}); record it with {BLESS_VAR}=1", path.display())
    });
    let mut file: Value = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("golden case `{name}`: {} is not valid JSON: {e}", path.display()));
    let expected_records = match file.as_object_mut().and_then(|o| o.remove("records")) {
        Some(Value::Array(r)) => r,
        _ => panic!("golden case `{name}`: {} has no `records` array", path.display()),
    };

    let mut problems = Vec::new();
    let records = to_values(&records);
    let mut diffs = Vec::new();
    differences("", &file, &header, &mut diffs);
    problems.extend(diffs.into_iter().map(|(p, e, a)| format!("header field `{p}`: expected {e}, got {a}")));
    if expected_records.len() != records.len() {
        problems.push(format!("expected {} records, got {}", expected_records.len(), records.len()));
    }
    for (i, (e, a)) in expected_records.iter().zip(&records).enumerate() {
        let mut diffs = Vec::new();
        differences("", e, a, &mut diffs);
        for (field, ev, av) in diffs {
            problems.push(format!("{}: field `{field}`: expected {ev}, got {av}", locate(i, e)));
        }
    }
    if !problems.is_empty() {
        let shown = problems.len().min(MAX_REPORTED);
        panic!(
            "golden case `{name}` differs from {} in {} place(s) (first {shown}):\n  {}\n\
             If the change of dynamics is deliberate, re-record with {BLESS_VAR}=1 and review the diff.",
            path.display(),
            problems.len(),
            problems[..shown].join("\n  ")
        );
    }
}

macro_rules! golden_tests {
    ($($test:ident),+ $(,)?) => {
        $(#[test]
        fn $test() {
            check(stringify!($test));
        })+

        /// The evolving line with the empty schedule is bit-for-bit today's line: it meets every
        /// golden file too. Never blessed from: the plain line defines the files.
        #[test]
        fn an_empty_evolution_schedule_changes_no_golden_trajectory() {
            if std::env::var(BLESS_VAR).is_ok_and(|v| v == "1") {
                return;
            }
            $(check_built(stringify!($test), empty_evolution, false);)+
        }

        /// Every case has a test and every file a case: a renamed case cannot leave its old
        /// file behind, nor a new case go untested.
        #[test]
        fn every_case_has_a_test_and_every_file_a_case() {
            let mut tested = vec![$(stringify!($test)),+];
            tested.sort();
            let mut defined: Vec<&str> = cases().iter().map(|c| c.name).collect();
            defined.sort();
            assert_eq!(tested, defined, "golden_tests! and cases() list different cases");
            if std::env::var(BLESS_VAR).is_ok_and(|v| v == "1") {
                return; // the files may not exist yet
            }
            let mut files: Vec<String> = fs::read_dir(golden_dir())
                .unwrap_or_else(|e| panic!("cannot list {}: {e}; record with {BLESS_VAR}=1", golden_dir().display()))
                .map(|entry| entry.expect("a directory entry").file_name().to_string_lossy().into_owned())
                .collect();
            files.sort();
            let wanted: Vec<String> = defined.iter().map(|n| format!("{n}.json")).collect();
            assert_eq!(files, wanted, "files in {} do not match the cases", golden_dir().display());
        }
    };
}

golden_tests!(basic_a_seed42, basic_d_seed7, advanced_b_seed42, advanced_c_seed3, advanced_seasonal3_seed11);

/// The comparison above is only exact if JSON parsing is: this value comes back one ULP off
/// with serde_json's default (best-effort) float parser.
#[test]
fn json_floats_round_trip_exactly() {
    let x = 0.099_459_522_831_109_59_f64;
    let text = serde_json::to_string(&x).unwrap();
    let back: f64 = serde_json::from_str(&text).unwrap();
    assert_eq!(x.to_bits(), back.to_bits(), "enable serde_json's `float_roundtrip` feature");
}

/// A golden file is only as good as the run is repeatable within one build.
#[test]
fn runs_are_repeatable() {
    for case in cases() {
        assert_eq!(to_values(&run(&case)), to_values(&run(&case)), "case {}", case.name);
    }
}
