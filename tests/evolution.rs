//! The evolving line (`--evolution FILE`): every event kind changes exactly what it names, from exactly its
//! tick or episode, and nothing before; the trajectory is fixed by schedule, seed and actions;
//! streams an event does not name do not move; bad schedules are refused naming the event; the
//! ready schedules in `bridge/sorting_line_gym/evolutions/` parse and run; random schedules never
//! panic and validate consistently. (The empty schedule against the golden files: tests/golden.rs.)
//!
//! Comparisons run the same seed and the same observation-independent actions with and without
//! the event, and compare every recorded field.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::Command;

use proptest::prelude::*;
use proptest::sample::select;
use serde_json::{json, Map, Value};
use sorting_line::sim::evolution::{category_code, At, Event, FaultKind, InputFault, Schedule, CATEGORY_UNKNOWN_CODE};
use sorting_line::sim::{Action, Category, InputKind, Line, LineConfig, Setup, SortMode, Variant};

/// Steps of a scripted run: three episodes (reset without a seed after 50 steps, with seed 77
/// after 100), 130 ticks.
const STEPS: usize = 130;

fn script_action(k: usize) -> Action {
    let p = k % 18;
    let speed = if p <= 9 { p } else { 18 - p };
    Action::new(speed, SortMode::from_index((k % 3) as u8).unwrap())
}

fn reset_after(k: usize) -> Option<Option<u64>> {
    match k {
        50 => Some(None),
        100 => Some(Some(77)),
        _ => None,
    }
}

/// Everything observable about the line after a record's event, one JSON object per record.
fn snapshot(line: &Line, event: &str, outcome: Option<&sorting_line::sim::StepOutcome>) -> Map<String, Value> {
    let c = line.containers();
    let o = line.observation();
    let mut m = json!({
        "event": event,
        "episode": line.episode(),
        "step": line.step_count(),
        "tick": line.tick(),
        "speed_index": line.speed_index(),
        "mode": line.mode(),
        "obs_quantity": o.quantity,
        "obs_category": o.category,
        "category_reading": category_code(line.category_reading()),
        "containers": [c.a, c.a_false, c.b, c.b_false],
        "input": [line.input().a, line.input().b],
        "belt": [line.belt().a, line.belt().b],
        "machine": [line.machine().a, line.machine().b],
        "cumulative_reward": line.cumulative_reward(),
        "settings": line.settings(),
    });
    if let Some(out) = outcome {
        m["reward"] = out.reward.into();
        m["accuracy"] = out.accuracy.into();
        m["occupancy"] = out.occupancy.into();
        m["speed_changed"] = out.speed_changed.into();
        m["applied_mode"] = json!(out.action.mode);
    }
    m.as_object().unwrap().clone()
}

fn run(config: &LineConfig, seed: u64, schedule: Schedule) -> Vec<Map<String, Value>> {
    let mut line = Line::with_evolution(config.clone(), seed, schedule);
    let mut records = vec![snapshot(&line, "new", None)];
    for k in 0..STEPS {
        if let Some(seed) = reset_after(k) {
            line.reset(seed);
            records.push(snapshot(&line, "reset", None));
        }
        let out = line.step(script_action(k));
        records.push(snapshot(&line, "step", Some(&out)));
    }
    records
}

/// Index of the first record that shows an event at `at`: the step record of tick T, or the
/// reset record that starts episode E.
fn first_affected(records: &[Map<String, Value>], at: At) -> usize {
    records
        .iter()
        .position(|r| match at {
            // A step record's `tick` is the line's counter after the step.
            At::Tick(t) => r["event"] == "step" && r["tick"] == json!(t + 1),
            At::Episode(e) => r["event"] != "step" && r["episode"] == json!(e),
        })
        .expect("the run reaches the event")
}

/// (record index, field) of every difference.
fn differences(base: &[Map<String, Value>], other: &[Map<String, Value>]) -> Vec<(usize, String)> {
    assert_eq!(base.len(), other.len());
    let mut out = Vec::new();
    for (i, (a, b)) in base.iter().zip(other).enumerate() {
        for (key, value) in a {
            if b.get(key) != Some(value) {
                out.push((i, key.clone()));
            }
        }
    }
    out
}

struct Expect {
    /// Fields that may differ from the first affected record on.
    may_change: &'static [&'static str],
    /// Fields that must differ in the first affected record (the change shows at once).
    at_once: &'static [&'static str],
    /// Fields that must differ in some record (the change has its effect).
    somewhere: &'static [&'static str],
}

fn check_event(name: &str, config: LineConfig, event: Event, expect: Expect) -> Vec<(usize, String)> {
    let at = event.at;
    let base = run(&config, 42, Schedule::default());
    let evolved = run(&config, 42, Schedule::new(vec![event]));
    let first = first_affected(&evolved, at);
    let diffs = differences(&base, &evolved);
    for (i, field) in &diffs {
        assert!(*i >= first, "{name}: record {i} ({field}) changed before the event's record {first}");
        assert!(expect.may_change.contains(&field.as_str()), "{name}: record {i}: `{field}` changed");
    }
    for field in expect.at_once {
        assert!(diffs.contains(&(first, field.to_string())), "{name}: `{field}` unchanged at record {first}");
    }
    let changed: BTreeSet<&str> = diffs.iter().map(|(_, f)| f.as_str()).collect();
    for field in expect.somewhere {
        assert!(changed.contains(field), "{name}: `{field}` never changed");
    }
    diffs
}

fn event(at: At, set: impl FnOnce(&mut Event)) -> Event {
    let mut e = Event::at(at);
    set(&mut e);
    e
}

const SETTINGS: &str = "settings";
const REWARD: &[&str] = &["settings", "reward", "cumulative_reward"];

#[test]
fn obs_noise_changes_the_readings_only() {
    for at in [At::Tick(20), At::Episode(1)] {
        check_event(
            "obs_noise",
            LineConfig::for_setup(Setup::A, Variant::Advanced),
            event(at, |e| e.obs_noise = Some(0.3)),
            // Input, accuracy and everything downstream untouched: the noise draw was always taken.
            Expect { may_change: &[SETTINGS, "obs_quantity"], at_once: &[SETTINGS], somewhere: &["obs_quantity"] },
        );
    }
}

#[test]
fn threshold_and_penalty_change_the_reward_only() {
    for at in [At::Tick(20), At::Episode(2)] {
        check_event(
            "threshold",
            LineConfig::for_setup(Setup::A, Variant::Basic),
            event(at, |e| e.threshold = Some(0.8)),
            Expect { may_change: REWARD, at_once: &[SETTINGS], somewhere: &["reward"] },
        );
        let config = LineConfig::for_setup(Setup::A, Variant::Advanced);
        let diffs = check_event(
            "action_penalty",
            config.clone(),
            event(at, |e| e.action_penalty = Some(2.0)),
            Expect { may_change: REWARD, at_once: &[SETTINGS], somewhere: &["reward"] },
        );
        // Only where the speed changed.
        let base = run(&config, 42, Schedule::default());
        for (i, field) in diffs {
            if field == "reward" {
                assert_eq!(base[i]["speed_changed"], json!(true), "record {i}");
            }
        }
    }
}

#[test]
fn input_generator_changes_the_material_from_its_tick() {
    let all: &[&str] = &[
        SETTINGS,
        "obs_quantity",
        "obs_category",
        "containers",
        "input",
        "belt",
        "machine",
        "reward",
        "accuracy",
        "occupancy",
        "cumulative_reward",
        "category_reading",
    ];
    for (at, kind) in [(At::Tick(20), InputKind::Seasonal3), (At::Episode(1), InputKind::Seasonal)] {
        check_event(
            "input",
            LineConfig::for_setup(Setup::A, Variant::Advanced),
            event(at, |e| e.input = Some(kind)),
            // Tick T's step draws the first batch of the new generator into the input.
            Expect { may_change: all, at_once: &[SETTINGS], somewhere: &["input", "belt", "machine", "reward"] },
        );
    }
    // Setting the input the line already has changes nothing at all.
    let config = LineConfig::for_setup(Setup::B, Variant::Basic);
    let same = run(&config, 42, Schedule::new(vec![event(At::Tick(20), |e| e.input = Some(InputKind::Seasonal))]));
    assert_eq!(same, run(&config, 42, Schedule::default()));
}

#[test]
fn machine_upgrade_changes_modes_and_sorting_not_the_material() {
    let sorting: &[&str] = &[SETTINGS, "mode", "applied_mode", "accuracy", "reward", "cumulative_reward", "containers"];
    for at in [At::Tick(20), At::Episode(1)] {
        // Setup A has no observation noise, so the readings cannot move either.
        check_event(
            "sort_modes on",
            LineConfig::for_setup(Setup::A, Variant::Basic),
            event(at, |e| e.sort_modes = Some(true)),
            Expect { may_change: sorting, at_once: &[SETTINGS], somewhere: &["mode", "accuracy", "containers"] },
        );
        check_event(
            "sort_modes off",
            LineConfig::for_setup(Setup::A, Variant::Advanced),
            event(at, |e| e.sort_modes = Some(false)),
            Expect { may_change: sorting, at_once: &[SETTINGS], somewhere: &["mode", "accuracy", "containers"] },
        );
    }
}

#[test]
fn sensor_upgrade_changes_the_category_reading_only() {
    for at in [At::Tick(20), At::Episode(1)] {
        check_event(
            "ratio_sensor on",
            LineConfig::for_setup(Setup::C, Variant::Basic),
            event(at, |e| e.ratio_sensor = Some(true)),
            Expect {
                may_change: &[SETTINGS, "category_reading"],
                at_once: &[SETTINGS, "category_reading"],
                somewhere: &[],
            },
        );
        check_event(
            "ratio_sensor off",
            LineConfig::for_setup(Setup::C, Variant::Advanced),
            event(at, |e| e.ratio_sensor = Some(false)),
            Expect {
                may_change: &[SETTINGS, "category_reading"],
                at_once: &[SETTINGS, "category_reading"],
                somewhere: &[],
            },
        );
    }
}

#[test]
fn input_faults_replace_exactly_n_readings_and_shift_no_stream() {
    const N: u32 = 6;
    // Setup C: noisy readings, so an unconsumed noise draw would show after the fault.
    let config = LineConfig::for_setup(Setup::C, Variant::Advanced);
    let base = run(&config, 42, Schedule::default());
    for kind in [FaultKind::Stuck, FaultKind::Dropped] {
        for at in [At::Tick(20), At::Tick(48), At::Episode(1)] {
            let fault = event(at, |e| e.input_fault = Some(InputFault { kind, ticks: N }));
            let evolved = run(&config, 42, Schedule::new(vec![fault]));
            let first = first_affected(&evolved, at);
            let before = base[first - 1]["obs_quantity"].clone();
            // The faulty records: the first affected one and every record until N steps passed.
            let mut steps_seen = 0;
            let mut faulty = vec![];
            for (i, r) in evolved.iter().enumerate().skip(first) {
                if steps_seen == N {
                    break;
                }
                faulty.push(i);
                if r["event"] == "step" {
                    steps_seen += 1;
                }
            }
            for (i, field) in differences(&base, &evolved) {
                assert!(field == "obs_quantity" || field == SETTINGS, "{kind:?} {at}: record {i} `{field}`");
                assert!(faulty.contains(&i), "{kind:?} {at}: record {i} `{field}` outside the fault {faulty:?}");
            }
            for &i in &faulty {
                let expected = match kind {
                    FaultKind::Stuck => before.clone(),
                    FaultKind::Dropped => json!(0.0),
                };
                assert_eq!(evolved[i]["obs_quantity"], expected, "{kind:?} {at}: record {i}");
            }
        }
    }
}

#[test]
fn a_fault_at_episode_zero_sticks_at_zero_and_a_new_fault_replaces_the_old() {
    let config = LineConfig::for_setup(Setup::A, Variant::Basic);
    let stuck = event(At::Episode(0), |e| e.input_fault = Some(InputFault { kind: FaultKind::Stuck, ticks: 3 }));
    let mut line = Line::with_evolution(config.clone(), 1, Schedule::new(vec![stuck]));
    assert_eq!(line.observation().quantity, 0.0);
    assert_eq!(line.settings().input_fault.unwrap().remaining, 3);
    for _ in 0..3 {
        assert_eq!(line.step(Action::new(2, SortMode::Basic)).observation.quantity, 0.0);
    }
    assert!(line.settings().input_fault.is_none());
    assert_ne!(line.step(Action::new(2, SortMode::Basic)).observation.quantity, 0.0);

    let dropped = event(At::Tick(2), |e| e.input_fault = Some(InputFault { kind: FaultKind::Dropped, ticks: 10 }));
    let stuck = event(At::Tick(4), |e| e.input_fault = Some(InputFault { kind: FaultKind::Stuck, ticks: 2 }));
    let mut line = Line::with_evolution(config, 1, Schedule::new(vec![dropped, stuck]));
    let readings: Vec<f64> = (0..8).map(|_| line.step(Action::new(2, SortMode::Basic)).observation.quantity).collect();
    assert!(readings[..2].iter().all(|&q| q > 0.0), "{readings:?}");
    // Dropped at ticks 2, 3; then stuck on the last (dropped) reading for two ticks; then healthy.
    assert_eq!(&readings[2..6], &[0.0; 4], "{readings:?}");
    assert!(readings[6..].iter().all(|&q| q > 0.0), "{readings:?}");
}

#[test]
fn without_the_machine_upgrade_only_mode_0_is_valid_and_other_modes_run_as_0() {
    let upgrade = event(At::Tick(3), |e| e.sort_modes = Some(true));
    let mut line =
        Line::with_evolution(LineConfig::for_setup(Setup::B, Variant::Basic), 5, Schedule::new(vec![upgrade]));
    for _ in 0..3 {
        assert!(line.mode_allowed(SortMode::Basic) && !line.mode_allowed(SortMode::Negative));
        let mask = line.action_mask();
        assert!((0..30).all(|a| mask[a] == (a % 3 == 0)), "{mask:?}");
        let out = line.step(Action::new(4, SortMode::Positive));
        assert_eq!((out.action.mode, line.mode()), (SortMode::Basic, SortMode::Basic));
    }
    // Tick 3 is the first with modes: its command runs as given.
    let out = line.step(Action::new(4, SortMode::Positive));
    assert_eq!(out.action.mode, SortMode::Positive);
    assert!(line.action_mask().iter().all(|&ok| ok));
}

#[test]
fn before_the_sensor_upgrade_the_category_is_unknown() {
    let upgrade = event(At::Episode(1), |e| e.ratio_sensor = Some(true));
    let mut line =
        Line::with_evolution(LineConfig::for_setup(Setup::A, Variant::Basic), 5, Schedule::new(vec![upgrade]));
    assert_eq!((line.category_reading(), category_code(line.category_reading())), (None, CATEGORY_UNKNOWN_CODE));
    line.step(Action::new(4, SortMode::Basic));
    assert_eq!(line.category_reading(), None);
    line.reset(None);
    assert_eq!(line.category_reading(), Some(line.observation().category));
    // A plain basic line has no ratio sensor either; an advanced one has.
    assert_eq!(Line::new(LineConfig::default(), 1).category_reading(), None);
    let advanced = Line::new(LineConfig { variant: Variant::Advanced, ..LineConfig::default() }, 1);
    assert_eq!(advanced.category_reading(), Some(advanced.observation().category));
}

/// After the paper's upgrade a seeded episode is exactly an advanced line's episode of that seed,
/// and an upgrade at episode 0 is an advanced line from the start.
#[test]
fn an_upgraded_line_is_an_advanced_line() {
    let upgrade = |at| {
        Schedule::new(vec![event(at, |e| {
            e.sort_modes = Some(true);
            e.ratio_sensor = Some(true);
        })])
    };
    let basic = LineConfig::for_setup(Setup::D, Variant::Basic);
    let advanced = LineConfig::for_setup(Setup::D, Variant::Advanced);
    let mut from_start = Line::with_evolution(basic.clone(), 9, upgrade(At::Episode(0)));
    let mut reference = Line::new(advanced.clone(), 9);
    let mut upgraded = Line::with_evolution(basic, 3, upgrade(At::Episode(2)));
    for k in 0..60 {
        upgraded.step(script_action(k));
    }
    upgraded.reset(None);
    assert_eq!(upgraded.reset(Some(9)), reference.observation());
    assert_eq!(from_start.observation(), reference.observation());
    for k in 0..120 {
        let expected = reference.step(script_action(k));
        assert_eq!(from_start.step(script_action(k)), expected, "step {k}");
        assert_eq!(upgraded.step(script_action(k)), expected, "step {k}");
        assert_eq!(upgraded.category_reading(), Some(expected.observation.category));
    }
    // So is a changed input at construction: a new line of that input.
    let seasonal = Schedule::new(vec![event(At::Episode(0), |e| e.input = Some(InputKind::Seasonal))]);
    let mut switched = Line::with_evolution(LineConfig::for_setup(Setup::A, Variant::Basic), 4, seasonal);
    let mut fresh =
        Line::new(LineConfig { input: InputKind::Seasonal, ..LineConfig::for_setup(Setup::A, Variant::Basic) }, 4);
    for k in 0..60 {
        assert_eq!(switched.step(script_action(k)), fresh.step(script_action(k)));
    }
}

fn rich_schedule() -> Schedule {
    Schedule::new(vec![
        event(At::Tick(7), |e| e.obs_noise = Some(0.25)),
        event(At::Episode(1), |e| {
            e.sort_modes = Some(true);
            e.input = Some(InputKind::Seasonal3);
        }),
        event(At::Tick(60), |e| e.input_fault = Some(InputFault { kind: FaultKind::Stuck, ticks: 4 })),
        event(At::Tick(60), |e| e.threshold = Some(0.75)),
        event(At::Episode(2), |e| e.ratio_sensor = Some(true)),
        event(At::Tick(110), |e| e.action_penalty = Some(0.4)),
    ])
}

#[test]
fn same_schedule_seed_and_actions_same_trajectory() {
    let config = LineConfig::for_setup(Setup::B, Variant::Basic);
    let a = run(&config, 11, rich_schedule());
    assert_eq!(a, run(&config, 11, rich_schedule()));
    assert_ne!(a, run(&config, 11, Schedule::default()));
    // A clone mid-run carries its progress through the schedule.
    let mut line = Line::with_evolution(config, 11, rich_schedule());
    for k in 0..55 {
        if k == 50 {
            line.reset(None);
        }
        line.step(script_action(k));
    }
    let mut twin = line.clone();
    for k in 55..130 {
        assert_eq!(line.step(script_action(k)), twin.step(script_action(k)));
        assert_eq!(line.settings(), twin.settings());
    }
}

#[test]
fn no_event_moves_the_input_stream_but_an_input_event() {
    let config = LineConfig::for_setup(Setup::C, Variant::Basic);
    let materials =
        |records: &[Map<String, Value>]| -> Vec<Value> { records.iter().map(|r| r["input"].clone()).collect() };
    let base = materials(&run(&config, 8, Schedule::default()));
    let mut schedule = rich_schedule();
    schedule.events.retain(|e| e.input.is_none());
    schedule.events.push(event(At::Tick(3), |e| e.obs_noise = Some(1.0)));
    schedule
        .events
        .push(event(At::Tick(30), |e| e.input_fault = Some(InputFault { kind: FaultKind::Dropped, ticks: 9 })));
    schedule.events.push(event(At::Tick(40), |e| e.sort_modes = Some(true)));
    assert_eq!(materials(&run(&config, 8, schedule)), base);
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sorting_line"))
}

fn write_temp(text: &str) -> tempfile::NamedTempFile {
    let mut file = tempfile::NamedTempFile::new().unwrap();
    std::io::Write::write_all(&mut file, text.as_bytes()).unwrap();
    file
}

#[test]
fn cli_refuses_a_bad_schedule_at_start_naming_the_event() {
    let bad =
        write_temp("events:\n  - at: {episode: 2}\n    sort_modes: true\n  - at: {tick: 500}\n    threshold: 1.2\n");
    let path = bad.path().display().to_string();
    for args in [
        vec!["trace", "--setup", "B", "--actions", "1,2", "--evolution", path.as_str()],
        vec!["eval", "--agent", "rba", "--setup", "B", "--episodes", "2", "--evolution", path.as_str()],
    ] {
        let out = bin().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty(), "{args:?}: nothing is printed before the refusal");
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(
            err.trim_end(),
            format!("sorting_line: --evolution {path}: evolution event 1 (at tick 500): threshold = 1.2 is out of range: allowed 0.0 ..< 1.0")
        );
    }
    let out = bin().args(["trace", "--setup", "A", "--evolution", "/nonexistent/evolution.yaml"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--evolution /nonexistent/evolution.yaml: "));
}

fn trace(args: &[&str]) -> Vec<Value> {
    let out = bin().arg("trace").args(args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

#[test]
fn trace_says_which_events_applied_where_and_agrees_with_the_library() {
    let file = write_temp(&serde_yaml::to_string(&rich_schedule()).unwrap());
    let path = file.path().display().to_string();
    let actions: Vec<String> = (0..STEPS + 2)
        .map(|k| match k {
            50 => "r".to_string(),
            101 => "r77".to_string(),
            _ => script_action(k).to_discrete(Variant::Advanced).to_string(),
        })
        .collect();
    let records = trace(&["--setup", "B", "--seed", "11", "--evolution", &path, "--actions", &actions.join(",")]);
    let applied: Vec<(String, u64, Vec<u64>)> = records
        .iter()
        .filter(|r| !r["evolution"].as_array().unwrap().is_empty())
        .map(|r| {
            let kind = if r.get("reset").is_some() { "reset" } else { "step" };
            let indices = r["evolution"].as_array().unwrap().iter().map(|e| e["index"].as_u64().unwrap()).collect();
            (kind.to_string(), r["tick"].as_u64().unwrap(), indices)
        })
        .collect();
    // Ticks 7, 60, 110; resets at tick 50 (episode 1) and 100 (episode 2).
    let expected = [
        ("step", 7, vec![0]),
        ("reset", 50, vec![1]),
        ("step", 60, vec![2, 3]),
        ("reset", 100, vec![4]),
        ("step", 110, vec![5]),
    ];
    assert_eq!(applied, expected.map(|(k, t, i)| (k.to_string(), t, i)));
    // The step records agree with the library, event for event.
    let mut line = Line::with_evolution(LineConfig::for_setup(Setup::B, Variant::Basic), 11, rich_schedule());
    for (token, record) in actions.iter().zip(&records[1..]) {
        match token.strip_prefix('r') {
            Some("") => {
                line.reset(None);
            }
            Some(seed) => {
                line.reset(Some(seed.parse().unwrap()));
            }
            None => {
                let out = line.step(Action::from_discrete(Variant::Advanced, token.parse().unwrap()).unwrap());
                assert_eq!(record["step"], serde_json::to_value(out).unwrap());
            }
        }
        assert_eq!(record["settings"], serde_json::to_value(line.settings()).unwrap());
        assert_eq!(record["category_reading"], json!(category_code(line.category_reading())));
    }
    // Without --evolution the output has none of these fields (unchanged for existing users).
    let plain = trace(&["--setup", "B", "--actions", "1,2"]);
    assert!(plain.iter().all(|r| r.get("evolution").is_none() && r.get("tick").is_none()));
}

#[test]
fn eval_reports_the_events_of_each_episode() {
    let file = write_temp("events:\n  - at: {episode: 3}\n    sort_modes: true\n    ratio_sensor: true\n");
    let path = file.path().display().to_string();
    let out = bin()
        .args([
            "eval",
            "--agent",
            "constant:5:cat",
            "--setup",
            "B",
            "--variant",
            "advanced",
            "--episodes",
            "4",
            "--json",
        ])
        .args(["--evolution", &path])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: Value = serde_json::from_slice(&out.stdout).unwrap();
    let events: Vec<Value> =
        summary["per_episode"].as_array().unwrap().iter().map(|e| e["evolution_events"].clone()).collect();
    assert_eq!(events, [Value::Null, Value::Null, json!([0]), Value::Null]);
    assert_eq!(summary["evolution"]["events"][0]["at"], json!({"episode": 3}));
}

/// The value `event` sets for `field`, as JSON (None: it leaves the field alone).
fn event_field(event: &Event, field: &str) -> Option<Value> {
    serde_json::to_value(event).unwrap().get(field).cloned()
}

fn evolutions_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("bridge/sorting_line_gym/evolutions")
}

#[test]
fn the_ready_schedules_parse_and_run() {
    let read =
        |name: &str| Schedule::from_yaml(&std::fs::read_to_string(evolutions_dir().join(name)).unwrap()).unwrap();
    let mut files: Vec<String> = std::fs::read_dir(evolutions_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(
        files,
        [
            "drift.yaml",
            "machine.yaml",
            "noise-drift.yaml",
            "sensor.yaml",
            "setup-a-to-b.yaml",
            "threshold-drift.yaml",
            "upgrade.yaml"
        ]
    );

    // The paper's upgrade: basic B, then advanced B.
    let upgrade = read("upgrade.yaml");
    let At::Episode(at) = upgrade.events.iter().map(|e| e.at).max().unwrap() else { panic!("episode events") };
    let mut line = Line::with_evolution(LineConfig::for_setup(Setup::B, Variant::Basic), 42, upgrade);
    let basic_b = line.settings();
    assert!(!basic_b.sort_modes && !basic_b.ratio_sensor);
    while line.episode() < at {
        for _ in 0..50 {
            line.step(Action::new(5, SortMode::Negative));
        }
        assert!(!line.sort_modes() && !line.ratio_sensor(), "episode {}", line.episode());
        line.reset(None);
    }
    let advanced_b = line.settings();
    assert!(advanced_b.sort_modes && advanced_b.ratio_sensor);
    assert_eq!(
        (advanced_b.input, advanced_b.obs_noise, advanced_b.action_penalty, advanced_b.threshold),
        (InputKind::Seasonal, 0.0, 0.5, 0.7)
    );

    // The drift: noise 0 -> 0.3, threshold 0.7 -> 0.8, in steps.
    let drift = read("drift.yaml");
    let last = drift.events.iter().map(|e| e.at).max().unwrap();
    let mut line = Line::with_evolution(LineConfig::for_setup(Setup::B, Variant::Basic), 42, drift);
    assert_eq!((line.config().obs_noise, line.config().threshold), (0.0, 0.7));
    let (mut noise, mut threshold) = (vec![], vec![]);
    while At::Episode(line.episode()) < last {
        for _ in 0..50 {
            line.step(Action::new(5, SortMode::Basic));
        }
        line.reset(None);
        noise.push(line.config().obs_noise);
        threshold.push(line.config().threshold);
    }
    assert_eq!((line.config().obs_noise, line.config().threshold), (0.3, 0.8));
    assert!(noise.windows(2).all(|w| w[0] <= w[1]) && threshold.windows(2).all(|w| w[0] <= w[1]), "monotone drift");

    // The transfer study's single-change scenarios: past their last event, the line has what their
    // events set, each field at its last value.
    for name in ["machine.yaml", "noise-drift.yaml", "sensor.yaml", "setup-a-to-b.yaml", "threshold-drift.yaml"] {
        let schedule = read(name);
        let At::Episode(last) = schedule.events.iter().map(|e| e.at).max().unwrap() else { panic!("{name}: episodes") };
        let mut line = Line::with_evolution(LineConfig::for_setup(Setup::B, Variant::Basic), 42, schedule.clone());
        while line.episode() <= last {
            for _ in 0..50 {
                line.step(Action::new(5, SortMode::Basic));
            }
            line.reset(None);
        }
        let got = line.settings();
        let events = &schedule.events;
        let last_set = |field: &str| events.iter().rev().find_map(|e| event_field(e, field));
        for field in ["obs_noise", "action_penalty", "threshold", "input", "sort_modes", "ratio_sensor"] {
            if let Some(want) = last_set(field) {
                let have = match field {
                    "obs_noise" => json!(got.obs_noise),
                    "action_penalty" => json!(got.action_penalty),
                    "threshold" => json!(got.threshold),
                    "input" => serde_json::to_value(got.input).unwrap(),
                    "sort_modes" => json!(got.sort_modes),
                    _ => json!(got.ratio_sensor),
                };
                assert_eq!(have, want, "{name}: {field} after the last event");
            }
        }
    }
}

// ---- random schedules ----

fn at() -> impl Strategy<Value = At> {
    prop_oneof![(0u32..5).prop_map(At::Episode), (0u64..200).prop_map(At::Tick)]
}

fn maybe<T: std::fmt::Debug + Clone + 'static>(
    s: impl Strategy<Value = T> + 'static,
) -> impl Strategy<Value = Option<T>> {
    prop_oneof![3 => Just(None), 1 => s.prop_map(Some)]
}

/// Values around and beyond each range, NaN included.
fn wide() -> impl Strategy<Value = f64> {
    prop_oneof![-1.0..12.0f64, Just(f64::NAN), Just(1.0), Just(0.0), Just(10.0)]
}

fn any_event() -> impl Strategy<Value = Event> {
    let fault = (select(vec![FaultKind::Stuck, FaultKind::Dropped]), 0u32..30)
        .prop_map(|(kind, ticks)| InputFault { kind, ticks });
    (
        at(),
        maybe(wide()),
        maybe(wide()),
        maybe(wide()),
        maybe(select(vec![InputKind::Random, InputKind::Seasonal, InputKind::Seasonal3])),
        maybe(any::<bool>()),
        maybe(any::<bool>()),
        maybe(fault),
    )
        .prop_map(|(at, obs_noise, action_penalty, threshold, input, sort_modes, ratio_sensor, input_fault)| {
            Event { at, obs_noise, action_penalty, threshold, input, sort_modes, ratio_sensor, input_fault }
        })
}

/// The ranges restated from docs/evolving.md, independently of the library's checks.
fn valid(e: &Event) -> bool {
    let within = |v: Option<f64>, lo: f64, hi: f64, hi_open: bool| {
        v.is_none_or(|v| v >= lo && if hi_open { v < hi } else { v <= hi })
    };
    let sets_something = e.obs_noise.is_some()
        || e.action_penalty.is_some()
        || e.threshold.is_some()
        || e.input.is_some()
        || e.sort_modes.is_some()
        || e.ratio_sensor.is_some()
        || e.input_fault.is_some();
    sets_something
        && within(e.obs_noise, 0.0, 1.0, false)
        && within(e.action_penalty, 0.0, 10.0, false)
        && within(e.threshold, 0.0, 1.0, true)
        && e.input_fault.is_none_or(|f| f.ticks >= 1)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_schedules_validate_consistently_and_run(
        events in prop::collection::vec(any_event(), 0..6),
        setup in select(vec![Setup::A, Setup::B, Setup::C, Setup::D]),
        variant in select(vec![Variant::Basic, Variant::Advanced]),
        seed in any::<u64>(),
        actions in prop::collection::vec((0usize..30, 0u8..12), 1..260),
    ) {
        let schedule = Schedule::new(events.clone());
        let verdict = schedule.validate();
        let first_bad = events.iter().position(|e| !valid(e));
        prop_assert_eq!(verdict.as_ref().err().map(|e| e.index), first_bad, "{:?}", verdict);
        if let Err(e) = &verdict {
            let text = e.to_string();
            let prefix = format!("evolution event {} (at {}): ", e.index, events[e.index].at);
            prop_assert!(text.starts_with(&prefix), "{}", text);
            // The file form is refused the same way (NaN has no YAML spelling serde_yaml reads back).
            if events.iter().all(|e| [e.obs_noise, e.action_penalty, e.threshold].iter().flatten().all(|v| v.is_finite())) {
                let yaml = serde_yaml::to_string(&schedule).unwrap();
                prop_assert_eq!(Schedule::from_yaml(&yaml).unwrap_err(), text);
            }
            return Ok(());
        }
        let yaml = serde_yaml::to_string(&schedule).unwrap();
        prop_assert_eq!(&Schedule::from_yaml(&yaml).unwrap(), &schedule);
        let config = LineConfig::for_setup(setup, variant);
        let mut line = Line::with_evolution(config.clone(), seed, schedule.clone());
        let mut twin = Line::with_evolution(config, seed, Schedule::from_yaml(&yaml).unwrap());
        for (a, r) in actions {
            if r == 0 {
                prop_assert_eq!(line.reset(None), twin.reset(None));
            } else if r == 1 {
                prop_assert_eq!(line.reset(Some(seed ^ 5)), twin.reset(Some(seed ^ 5)));
            } else {
                let action = Action::from_discrete(Variant::Advanced, a).unwrap();
                let out = line.step(action);
                prop_assert_eq!(out, twin.step(action));
                prop_assert!((0.0..=1.0).contains(&out.observation.quantity));
                prop_assert!(line.sort_modes() || out.action.mode == SortMode::Basic);
                prop_assert_eq!(out.action.mode == action.mode || !line.mode_allowed(action.mode), true);
            }
            prop_assert_eq!(line.accounted(), line.entered());
            prop_assert_eq!(line.category_reading().is_some(), line.ratio_sensor());
            prop_assert!(line.category_reading().is_none_or(|c| c == line.observation().category));
            prop_assert!(matches!(line.observation().category, Category::Basic | Category::Positive | Category::Negative));
        }
    }
}
