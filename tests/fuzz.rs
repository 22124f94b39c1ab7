//! Fuzzing of everything the node takes from outside, at the message level and without DDS
//! (proptest): commands (speeds, sort modes, stamps, senders) through the command protocol of a
//! hosted line, batch commands and batch resets (malformed lengths, bad entries, other lines'
//! owners) through the batch rules, parameter files (structured and random YAML) through the parameter loader, and
//! `--ros-args` through its parser.
//!
//! Properties:
//! - nothing panics;
//! - commands: a line that receives a flood of bad commands around the good ones follows exactly
//!   the trajectory of a line that receives only the good ones, every bad command is rejected with
//!   the reason an independent oracle expects, every rejection is counted by the per-line counters
//!   that /diagnostics publishes, and after the flood a clean seeded episode equals the library's;
//! - batches: a malformed `batch/cmd` changes no line and counts one malformed rejection; every
//!   entry of a well-formed one meets the same oracle as the per-line commands, and the lines
//!   follow lines fed only the accepted commands; a `batch/reset` is refused exactly when its
//!   lists differ in length or a line is out of range or repeated;
//! - parameters and `--ros-args`: a failure is an error message that names what was wrong (the
//!   file, the key or the argument), never a panic, and an accepted set of parameters is valid.
//!
//! Sizes: `SORTING_LINE_FUZZ_CASES` (default 256 cases per property; the full reliability run uses
//! 20,000: see docs/reliability.md). Each property prints how many cases and commands it tried
//! (`cargo test --release --test fuzz -- --nocapture`).

use std::collections::BTreeMap;
use std::io::Write;

use proptest::prelude::*;
use proptest::sample::select;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use sorting_line::ros::clock::SimClock;
use sorting_line::ros::diagnostics::LineCounters;
use sorting_line::ros::messages::{LineCommands, ResetLinesRequest, Time};
use sorting_line::ros::names::Names;
use sorting_line::ros::options::{NodeArgs, TickMode};
use sorting_line::ros::params::{load_params_file, NodeParams, PARAMETERS};
use sorting_line::ros::protocol::{
    batch_commands, batch_resets, Accepted, BatchModes, BatchReset, Client, Command, HostedLine, Rejection, TimerTick,
    REJECTIONS,
};
use sorting_line::ros::ros_args::RosArgs;
use sorting_line::ros::topics;
use sorting_line::sim::config::{SETUPS, VARIANTS};
use sorting_line::sim::{Line, LineConfig, SortMode, Variant};

const OWNER: Client = [1; 12];
const STRANGER: Client = [2; 12];
const PERIOD: f64 = 0.5;

fn cases() -> u32 {
    std::env::var("SORTING_LINE_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(256)
}

fn runner() -> TestRunner {
    TestRunner::new(Config { cases: cases(), failure_persistence: None, ..Config::default() })
}

// ------------------------------------------------------------------------------------------
// Commands

/// Which stamp a bad command carries, relative to the tick the line waits at.
#[derive(Clone, Copy, Debug)]
enum StampKind {
    Current,
    /// Another tick (may be negative or far away).
    Ticks(i64),
    /// Off the tick grid by some nanoseconds.
    Nanos(i64),
    /// Anything at all.
    Raw(i32, u32),
    /// The current time written with nanosec >= 1e9 (not a valid ROS time; aliases the tick).
    Unnormalized,
}

#[derive(Clone, Copy, Debug)]
enum Junk {
    Speed { stranger: bool, stamp: StampKind, speed: f64 },
    Mode { stranger: bool, stamp: StampKind, mode: u8 },
}

/// One tick of the clean run: the action, and the junk sent before the mode, between mode and
/// speed, and after the speed (when the line already waits at the next tick).
#[derive(Clone, Debug)]
struct Round {
    speed_index: usize,
    mode: u8,
    junk: [Vec<Junk>; 3],
}

fn speed_value() -> impl Strategy<Value = f64> {
    prop_oneof![
        3 => (0usize..10).prop_map(|i| (i + 1) as f64 / 10.0),
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(0.0),
        1 => Just(-0.3),
        1 => Just(1.1),
        1 => Just(0.55),
        1 => (0usize..10).prop_map(|i| (i + 1) as f64 / 10.0 + 2e-6),
        2 => any::<f64>(),
        1 => -2.0..3.0f64,
    ]
}

fn stamp_kind() -> impl Strategy<Value = StampKind> {
    prop_oneof![
        4 => Just(StampKind::Current),
        2 => (-3i64..=3).prop_map(StampKind::Ticks),
        1 => any::<i64>().prop_map(|t| StampKind::Ticks(t >> 20)),
        1 => (-1_000_000i64..1_000_000).prop_map(StampKind::Nanos),
        1 => (any::<i32>(), any::<u32>()).prop_map(|(s, n)| StampKind::Raw(s, n)),
        1 => Just(StampKind::Unnormalized),
    ]
}

fn junk() -> impl Strategy<Value = Junk> {
    let stranger = prop::bool::weighted(0.3);
    prop_oneof![
        (stranger, stamp_kind(), speed_value()).prop_map(|(stranger, stamp, speed)| Junk::Speed {
            stranger,
            stamp,
            speed
        }),
        (stranger, stamp_kind(), prop_oneof![3 => 0u8..3, 1 => any::<u8>()])
            .prop_map(|(stranger, stamp, mode)| Junk::Mode { stranger, stamp, mode }),
    ]
}

fn rounds() -> impl Strategy<Value = Vec<Round>> {
    let junk_list = || prop::collection::vec(junk(), 0..4);
    let round = (0usize..10, 0u8..3, junk_list(), junk_list(), junk_list())
        .prop_map(|(speed_index, mode, a, b, c)| Round { speed_index, mode, junk: [a, b, c] });
    prop::collection::vec(round, 1..60)
}

fn stamp_of(kind: StampKind, line: &HostedLine) -> Time {
    let clock = SimClock::new(PERIOD);
    let now = line.stamp();
    match kind {
        StampKind::Current => now,
        StampKind::Ticks(dt) => match line.tick().checked_add_signed(dt) {
            Some(t) if t <= 1 << 30 => clock.stamp(t),
            _ => Time { sec: -1, nanosec: 5 },
        },
        StampKind::Nanos(dn) => {
            let n = now.nanos() + if dn == 0 { 1 } else { dn };
            if n < 0 {
                Time { sec: -1, nanosec: 0 }
            } else {
                Time::from_nanos(n as u64)
            }
        }
        StampKind::Raw(sec, nanosec) => Time { sec, nanosec },
        StampKind::Unnormalized if now.sec > 0 => Time { sec: now.sec - 1, nanosec: now.nanosec + 1_000_000_000 },
        StampKind::Unnormalized => Time { sec: now.sec, nanosec: now.nanosec.wrapping_add(2_000_000_000) },
    }
}

/// A command as the oracle sees it: who sent it, its stamp, which topic, and whether its value
/// is one the line knows.
#[derive(Clone, Copy)]
struct Sent {
    from: Client,
    stamp: Time,
    is_speed: bool,
    valid: bool,
}

/// The oracle: what the protocol must answer to a command, from the documented rules alone.
/// `None` = it must be accepted (such junk is not sent: it would be a good command).
fn expected(
    line: &HostedLine,
    advanced: bool,
    lockstep: bool,
    sent: Sent,
    pending: bool,
) -> Option<&'static [Rejection]> {
    let Sent { from, stamp, is_speed, valid } = sent;
    if line.owner().is_some_and(|o| o != from) {
        return Some(&[Rejection::NotOwner]);
    }
    if !is_speed && !advanced {
        return Some(&[Rejection::ModeOnBasicLine]);
    }
    if !valid {
        return Some(if is_speed { &[Rejection::InvalidSpeed] } else { &[Rejection::UnknownMode] });
    }
    let exact = stamp == line.stamp();
    if lockstep {
        if !exact {
            return Some(&[Rejection::Stale, Rejection::UnknownTick]);
        }
        if line.line().truncated() {
            return Some(&[Rejection::EpisodeOver]);
        }
        if pending {
            return Some(&[Rejection::Duplicate]);
        }
        return None;
    }
    // Realtime: only stamps no newer than now are accepted; junk keeps to those it must refuse.
    if stamp.nanosec >= 1_000_000_000 || stamp.nanos() > line.stamp().nanos() {
        return Some(&[Rejection::UnknownTick]);
    }
    None
}

fn valid_speed(speed: f64) -> bool {
    (1..=10).any(|k| (speed - k as f64 / 10.0).abs() <= 1e-6)
}

struct Tally {
    commands: u64,
    rejected: BTreeMap<Rejection, u64>,
    skipped: u64,
}

/// Sends one junk command to `noisy` (unless the oracle says it would be accepted) and checks the answer.
fn send_junk(
    noisy: &mut HostedLine,
    counters: &mut LineCounters,
    tally: &mut Tally,
    j: Junk,
    lockstep: bool,
    pending: (bool, bool),
) -> Result<(), TestCaseError> {
    let advanced = noisy.line().config().variant == Variant::Advanced;
    let (from, stamp, is_speed, valid, value) = match j {
        Junk::Speed { stranger, stamp, speed } => {
            (if stranger { STRANGER } else { OWNER }, stamp_of(stamp, noisy), true, valid_speed(speed), speed)
        }
        Junk::Mode { stranger, stamp, mode } => {
            (if stranger { STRANGER } else { OWNER }, stamp_of(stamp, noisy), false, mode < 3, f64::from(mode))
        }
    };
    let pending = if is_speed { pending.0 } else { pending.1 };
    let Some(allowed) = expected(noisy, advanced, lockstep, Sent { from, stamp, is_speed, valid }, pending) else {
        tally.skipped += 1;
        return Ok(());
    };
    let before = (noisy.tick(), noisy.line().last_step().copied(), noisy.owner());
    let got =
        if is_speed { noisy.speed_from(from, stamp, value) } else { noisy.sort_mode_from(from, stamp, value as u8) };
    tally.commands += 1;
    let reason = match got {
        Err(reason) => reason,
        Ok(ok) => return Err(TestCaseError::fail(format!("{j:?} (stamp {stamp:?}) was accepted: {ok:?}"))),
    };
    prop_assert!(
        allowed.contains(&reason),
        "{j:?} (stamp {stamp:?}): rejected as {reason:?}, expected one of {allowed:?}"
    );
    prop_assert_eq!(
        before,
        (noisy.tick(), noisy.line().last_step().copied(), noisy.owner()),
        "a rejected command changed the line"
    );
    *tally.rejected.entry(reason).or_default() += 1;
    counters.reject(reason, if is_speed { topics::SPEED_CMD.name } else { topics::SORT_MODE_CMD.name }, "fuzz");
    Ok(())
}

fn clean_step(line: &mut HostedLine, r: &Round, advanced: bool) -> Result<Option<Accepted>, Rejection> {
    let stamp = line.stamp();
    if advanced {
        line.sort_mode_from(OWNER, stamp, r.mode)?;
    }
    line.speed_from(OWNER, stamp, (r.speed_index + 1) as f64 / 10.0).map(Some)
}

fn check_counters(counters: &mut LineCounters, tally: &Tally) -> Result<(), TestCaseError> {
    let status = counters.status(vec![]);
    let get = |k: &str| status.values.iter().find(|v| v.key == k).map(|v| v.value.clone()).unwrap_or_default();
    let total: u64 = tally.rejected.values().sum();
    prop_assert_eq!(get("commands_rejected"), total.to_string());
    for reason in REJECTIONS {
        let want = tally.rejected.get(&reason).copied().unwrap_or(0);
        prop_assert_eq!(get(&format!("rejected_{}", reason.key())), want.to_string(), "reason {}", reason.key());
    }
    Ok(())
}

/// After the flood: a clean seeded episode on the fuzzed line equals a fresh library line.
fn clean_replay(line: &mut HostedLine, config: &LineConfig, seed: u64, lockstep: bool) -> Result<(), TestCaseError> {
    line.reset(Some(seed));
    let mut reference = Line::new(config.clone(), seed);
    let advanced = config.variant == Variant::Advanced;
    for k in 0..config.max_steps.min(30) as usize {
        let (speed_index, mode) = (k * 7 % 10, (k % 3) as u8);
        let action =
            sorting_line::sim::Action::new(speed_index, SortMode::from_index(if advanced { mode } else { 0 }).unwrap());
        let want = reference.step(action);
        let r = Round { speed_index, mode, junk: Default::default() };
        let got = if lockstep {
            match clean_step(line, &r, advanced) {
                Ok(Some(Accepted::Stepped(out))) => out,
                other => return Err(TestCaseError::fail(format!("clean replay step {k}: {other:?}"))),
            }
        } else {
            clean_step(line, &r, advanced).map_err(|e| TestCaseError::fail(format!("clean replay step {k}: {e:?}")))?;
            match line.timer_tick() {
                TimerTick::Stepped(out) => out,
                TimerTick::Reset(_) => return Err(TestCaseError::fail("clean replay: unexpected restart")),
            }
        };
        prop_assert_eq!(got, want, "clean replay after the fuzz, step {}", k);
    }
    Ok(())
}

fn fuzz_commands(lockstep: bool) -> (u32, u64, u64, BTreeMap<Rejection, u64>) {
    let mode = if lockstep { TickMode::Lockstep } else { TickMode::Realtime };
    let strategy =
        (select(SETUPS.to_vec()), select(VARIANTS.to_vec()), 1u32..=25, any::<u64>(), any::<u64>(), rounds());
    let mut totals = (0u32, 0u64, 0u64, BTreeMap::new());
    let totals_cell = std::cell::RefCell::new(&mut totals);
    runner()
        .run(&strategy, |(setup, variant, max_steps, seed, replay_seed, rounds)| {
            let config = LineConfig { max_steps, ..LineConfig::for_setup(setup, variant) };
            let advanced = variant == Variant::Advanced;
            let clock = SimClock::new(PERIOD);
            let mut clean = HostedLine::new(config.clone(), seed, clock, mode);
            let mut noisy = HostedLine::new(config.clone(), seed, clock, mode);
            let mut counters = LineCounters::new("/fuzz".into());
            let mut tally = Tally { commands: 0, rejected: BTreeMap::new(), skipped: 0 };
            for r in &rounds {
                if clean.line().truncated() {
                    // Junk at an episode's end meets EpisodeOver (lock-step); then both restart
                    // (lock-step: a reset; realtime: the line's own restart on the next timer tick).
                    for &j in &r.junk[0] {
                        send_junk(&mut noisy, &mut counters, &mut tally, j, lockstep, (false, false))?;
                    }
                    if lockstep {
                        clean.reset(None);
                        noisy.reset(None);
                    } else {
                        prop_assert_eq!(clean.timer_tick(), noisy.timer_tick());
                    }
                    continue;
                }
                for &j in &r.junk[0] {
                    send_junk(&mut noisy, &mut counters, &mut tally, j, lockstep, (false, false))?;
                }
                let stamp = clean.stamp();
                if advanced {
                    let a = clean.sort_mode_from(OWNER, stamp, r.mode);
                    let b = noisy.sort_mode_from(OWNER, stamp, r.mode);
                    prop_assert_eq!(a, b);
                    prop_assert!(a.is_ok(), "the clean mode command was refused: {:?}", a);
                }
                for &j in &r.junk[1] {
                    send_junk(&mut noisy, &mut counters, &mut tally, j, lockstep, (false, advanced && lockstep))?;
                }
                let speed = (r.speed_index + 1) as f64 / 10.0;
                let a = clean.speed_from(OWNER, stamp, speed);
                let b = noisy.speed_from(OWNER, stamp, speed);
                prop_assert_eq!(a, b);
                prop_assert!(a.is_ok(), "the clean speed command was refused: {:?}", a);
                if !lockstep {
                    prop_assert_eq!(clean.timer_tick(), noisy.timer_tick());
                }
                for &j in &r.junk[2] {
                    send_junk(&mut noisy, &mut counters, &mut tally, j, lockstep, (false, false))?;
                }
                prop_assert_eq!(clean.tick(), noisy.tick());
                prop_assert_eq!(clean.line().last_step(), noisy.line().last_step());
                prop_assert_eq!(clean.line().observation(), noisy.line().observation());
            }
            check_counters(&mut counters, &tally)?;
            clean_replay(&mut noisy, &config, replay_seed, lockstep)?;
            let mut t = totals_cell.borrow_mut();
            t.0 += 1;
            t.1 += tally.commands;
            t.2 += tally.skipped;
            for (reason, n) in tally.rejected {
                *t.3.entry(reason).or_default() += n;
            }
            Ok(())
        })
        .unwrap();
    totals
}

fn report_commands(name: &str, (cases, commands, skipped, by_reason): (u32, u64, u64, BTreeMap<Rejection, u64>)) {
    let reasons: Vec<String> = by_reason.iter().map(|(r, n)| format!("{} {n}", r.key())).collect();
    eprintln!(
        "fuzz {name}: {cases} cases, {commands} bad commands rejected as expected ({}); {skipped} generated commands \
         were valid and not sent",
        reasons.join(", ")
    );
    for reason in REJECTIONS {
        // Malformed comes from decoding, Stopped from the simulation state (STOPPED) and SortModesOff
        // from an evolving line without modes, not from a command's content: the protocol's unit
        // tests, test_simulation_interfaces.py and test_evolving.py cover them.
        let reachable = !matches!(reason, Rejection::Malformed | Rejection::SortModesOff | Rejection::Stopped)
            && (name == "lockstep"
                || !matches!(reason, Rejection::Stale | Rejection::Duplicate | Rejection::EpisodeOver));
        if reachable && cases >= 64 {
            assert!(by_reason.contains_key(&reason), "the fuzz never produced a {} rejection", reason.key());
        }
    }
}

#[test]
fn fuzz_lockstep_commands() {
    report_commands("lockstep", fuzz_commands(true));
}

#[test]
fn fuzz_realtime_commands() {
    report_commands("realtime", fuzz_commands(false));
}

// ------------------------------------------------------------------------------------------
// Batches

/// One line's entry of a fuzzed `batch/cmd`.
#[derive(Clone, Copy, Debug)]
struct Entry {
    stranger: bool,
    stamp: StampKind,
    speed: f64,
    mode: u8,
}

/// A `batch/cmd`: its entries (the first `lines` are used) and, if `Some((list, longer))`, one
/// list (0 stamp_sec, 1 stamp_nanosec, 2 speeds, 3 modes) made one entry longer or shorter.
#[derive(Clone, Debug)]
struct Batch {
    entries: Vec<Entry>,
    misshapen: Option<(usize, bool)>,
}

fn entry() -> impl Strategy<Value = Entry> {
    let good = (0usize..10, 0u8..3).prop_map(|(i, mode)| Entry {
        stranger: false,
        stamp: StampKind::Current,
        speed: (i + 1) as f64 / 10.0,
        mode,
    });
    let bad = (prop::bool::weighted(0.3), stamp_kind(), speed_value(), prop_oneof![3 => 0u8..3, 1 => any::<u8>()])
        .prop_map(|(stranger, stamp, speed, mode)| Entry { stranger, stamp, speed, mode });
    prop_oneof![2 => good, 1 => bad]
}

fn batches() -> impl Strategy<Value = Vec<Batch>> {
    let misshapen = prop_oneof![4 => Just(None), 1 => (0usize..4, any::<bool>()).prop_map(Some)];
    let batch =
        (prop::collection::vec(entry(), 4), misshapen).prop_map(|(entries, misshapen)| Batch { entries, misshapen });
    prop::collection::vec(batch, 1..40)
}

/// The message for `batch` on `hosts`, each entry's stamp taken relative to its own line.
fn batch_message(batch: &Batch, hosts: &[HostedLine]) -> LineCommands {
    let entries = &batch.entries[..hosts.len()];
    let stamps: Vec<Time> = entries.iter().zip(hosts).map(|(e, h)| stamp_of(e.stamp, h)).collect();
    let mut cmd = LineCommands {
        stamp_sec: stamps.iter().map(|t| t.sec).collect(),
        stamp_nanosec: stamps.iter().map(|t| t.nanosec).collect(),
        speeds: entries.iter().map(|e| e.speed).collect(),
        modes: entries.iter().map(|e| e.mode).collect(),
        ..LineCommands::default()
    };
    if let Some((list, longer)) = batch.misshapen {
        // On the basic line an empty `modes` is allowed: make that list longer, never empty.
        let longer = longer || (list == 3 && hosts.len() == 1);
        match (list, longer) {
            (0, true) => cmd.stamp_sec.push(0),
            (0, false) => drop(cmd.stamp_sec.pop()),
            (1, true) => cmd.stamp_nanosec.push(0),
            (1, false) => drop(cmd.stamp_nanosec.pop()),
            (2, true) => cmd.speeds.push(0.5),
            (2, false) => drop(cmd.speeds.pop()),
            (_, true) => cmd.modes.push(0),
            (_, false) => drop(cmd.modes.pop()),
        }
    }
    cmd
}

#[test]
fn fuzz_batch_commands() {
    let strategy = (select(SETUPS.to_vec()), select(VARIANTS.to_vec()), 1usize..=4, any::<u64>(), batches());
    let totals = std::cell::RefCell::new((0u32, 0u64, BTreeMap::<Rejection, u64>::new()));
    runner()
        .run(&strategy, |(setup, variant, lines, seed, batches)| {
            let config = LineConfig::for_setup(setup, variant);
            let advanced = variant == Variant::Advanced;
            let clock = SimClock::new(PERIOD);
            let new_lines = || -> Vec<HostedLine> {
                (0..lines)
                    .map(|k| HostedLine::new(config.clone(), seed + k as u64, clock, TickMode::Lockstep))
                    .collect()
            };
            let (mut clean, mut noisy) = (new_lines(), new_lines());
            let mut counters: Vec<LineCounters> =
                (0..lines).map(|k| LineCounters::new(format!("/fuzz/line_{k}"))).collect();
            let mut tallies: Vec<Tally> =
                (0..lines).map(|_| Tally { commands: 0, rejected: BTreeMap::new(), skipped: 0 }).collect();
            // Per line: whether a speed and a mode already wait for the current tick.
            let mut pending = vec![(false, false); lines];
            for batch in &batches {
                let cmd = batch_message(batch, &noisy);
                let entries = match batch_commands(&cmd, lines, BatchModes::of(variant, false)) {
                    Err(detail) => {
                        prop_assert!(batch.misshapen.is_some(), "a well-formed batch was refused: {detail}");
                        prop_assert!(detail.contains(&format!("for {lines} lines")), "{detail}");
                        // No line sees any of it; the node counts it once, on line 0.
                        *tallies[0].rejected.entry(Rejection::Malformed).or_default() += 1;
                        counters[0].reject(Rejection::Malformed, topics::BATCH_CMD.name, &detail);
                        continue;
                    }
                    Ok(entries) => entries,
                };
                prop_assert!(batch.misshapen.is_none(), "a misshapen batch was accepted: {cmd:?}");
                for (k, entry) in entries.iter().enumerate() {
                    let from = if batch.entries[k].stranger { STRANGER } else { OWNER };
                    for command in entry.commands() {
                        let (is_speed, valid) = match command {
                            Command::Speed(speed) => (true, valid_speed(speed)),
                            Command::Mode(mode) => (false, mode < 3),
                        };
                        let waiting = if is_speed { pending[k].0 } else { pending[k].1 };
                        let allowed = expected(
                            &noisy[k],
                            advanced,
                            true,
                            Sent { from, stamp: entry.stamp, is_speed, valid },
                            waiting,
                        );
                        let got = noisy[k].command_from(from, entry.stamp, command);
                        tallies[k].commands += 1;
                        match (allowed, got) {
                            (None, Ok(accepted)) => {
                                prop_assert_eq!(clean[k].command_from(from, entry.stamp, command), Ok(accepted));
                                match accepted {
                                    Accepted::Stepped(_) => pending[k] = (false, false),
                                    Accepted::Stored if is_speed => pending[k].0 = true,
                                    Accepted::Stored => pending[k].1 = true,
                                }
                            }
                            (Some(allowed), Err(reason)) => {
                                prop_assert!(
                                    allowed.contains(&reason),
                                    "line {k}, {command} at {:?}: {reason:?}, expected one of {allowed:?}",
                                    entry.stamp
                                );
                                *tallies[k].rejected.entry(reason).or_default() += 1;
                                counters[k].reject(reason, topics::BATCH_CMD.name, "fuzz");
                            }
                            (allowed, got) => {
                                return Err(TestCaseError::fail(format!(
                                    "line {k}, {command} at {:?} from {from:?}: got {got:?}, expected {allowed:?}",
                                    entry.stamp
                                )))
                            }
                        }
                    }
                }
                for k in 0..lines {
                    prop_assert_eq!(clean[k].tick(), noisy[k].tick());
                    prop_assert_eq!(clean[k].line().last_step(), noisy[k].line().last_step(), "line {}", k);
                }
            }
            let mut t = totals.borrow_mut();
            t.0 += 1;
            for (c, tally) in counters.iter_mut().zip(&tallies) {
                check_counters(c, tally)?;
                t.1 += tally.commands;
                for (reason, n) in &tally.rejected {
                    *t.2.entry(*reason).or_default() += n;
                }
            }
            Ok(())
        })
        .unwrap();
    let (cases, commands, by_reason) = totals.into_inner();
    let reasons: Vec<String> = by_reason.iter().map(|(r, n)| format!("{} {n}", r.key())).collect();
    eprintln!(
        "fuzz batch commands: {cases} cases, {commands} entries' commands judged as expected ({})",
        reasons.join(", ")
    );
    if cases >= 64 {
        for reason in [
            Rejection::Malformed,
            Rejection::InvalidSpeed,
            Rejection::UnknownMode,
            Rejection::Stale,
            Rejection::UnknownTick,
            Rejection::NotOwner,
            Rejection::Duplicate,
        ] {
            assert!(by_reason.contains_key(&reason), "the batch fuzz never produced a {} rejection", reason.key());
        }
    }
}

#[test]
fn fuzz_batch_resets() {
    let list = |max: u32| prop::collection::vec(prop_oneof![4 => 0..max, 1 => any::<u32>()], 0..6);
    let strategy =
        (1usize..=5, list(6), prop::collection::vec(any::<bool>(), 0..6), prop::collection::vec(any::<u64>(), 0..6));
    let refused = std::cell::Cell::new(0u32);
    runner()
        .run(&strategy, |(lines, mut ids, mut has_seed, mut seeds)| {
            // Mostly well-shaped: trim the three lists to one length two times in three.
            if ids.len() % 3 != 0 {
                let n = ids.len().min(has_seed.len()).min(seeds.len());
                ids.truncate(n);
                has_seed.truncate(n);
                seeds.truncate(n);
            }
            let request = ResetLinesRequest { lines: ids.clone(), has_seed: has_seed.clone(), seeds: seeds.clone() };
            let same_length = ids.len() == has_seed.len() && ids.len() == seeds.len();
            let mut sorted = ids.clone();
            sorted.sort_unstable();
            sorted.dedup();
            let valid = same_length && sorted.len() == ids.len() && ids.iter().all(|&k| (k as usize) < lines);
            match batch_resets(&request, lines) {
                Ok(resets) => {
                    prop_assert!(valid, "{request:?} on {lines} lines was accepted");
                    let want: Vec<BatchReset> = (0..ids.len())
                        .map(|i| BatchReset { line: ids[i] as usize, seed: has_seed[i].then_some(seeds[i]) })
                        .collect();
                    prop_assert_eq!(resets, want);
                }
                Err(e) => {
                    prop_assert!(!valid, "{request:?} on {lines} lines was refused: {e}");
                    let named =
                        if same_length { e.contains("out of range or repeated") } else { e.contains("same length") };
                    prop_assert!(named, "{e}");
                    refused.set(refused.get() + 1);
                }
            }
            Ok(())
        })
        .unwrap();
    eprintln!("fuzz batch resets: {} cases, {} refused naming why", cases(), refused.get());
}

// ------------------------------------------------------------------------------------------
// Parameter files

fn yaml_scalar() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<i64>().prop_map(|v| v.to_string()),
        any::<u64>().prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        (-2.0..2.0f64).prop_map(|v| format!("{v}")),
        (0u32..100).prop_map(|v| v.to_string()),
        select(vec![
            "true",
            "false",
            "null",
            "~",
            ".nan",
            ".inf",
            "-.inf",
            "basic",
            "advanced",
            "random",
            "seasonal",
            "seasonal3",
            "lockstep",
            "realtime",
            "''",
            "\"x\"",
            "[1, 2]",
            "{a: 1}",
            "[",
            "{",
            "'unclosed",
            "0x1F",
            "1e400",
            "-1",
            "18446744073709551616",
            "&anchor 1",
            "*alias",
            "!!binary aGk=",
            "- 1",
        ])
        .prop_map(String::from),
    ]
}

fn yaml_key() -> impl Strategy<Value = String> {
    let known: Vec<String> = PARAMETERS.iter().map(|(n, _)| n.to_string()).collect();
    prop_oneof![
        4 => select(known),
        1 => "[a-z_]{1,12}",
        1 => select(vec!["1", "? complex", "\"quoted key\"", "null", "[k]"]).prop_map(String::from),
    ]
}

/// A parameter file: flat, launch_ros form (ours or another node's section), or random text.
fn params_file() -> impl Strategy<Value = String> {
    let body = || prop::collection::vec((yaml_key(), yaml_scalar()), 0..8);
    prop_oneof![
        3 => body().prop_map(|kv| kv.iter().map(|(k, v)| format!("{k}: {v}\n")).collect()),
        3 => (select(vec!["/**", "sorting_line", "/plant/sorting_line", "other_node", "/**/x"]), body()).prop_map(
            |(section, kv)| {
                let mut s = format!("{section}:\n  ros__parameters:\n");
                for (k, v) in kv {
                    s.push_str(&format!("    {k}: {v}\n"));
                }
                s
            }
        ),
        1 => select(vec!["/**:\n  ros__parameters: 3\n", "/**:\n  ros__parameters:\n", "- a\n- b\n", "42\n", "",
                         "a: b: c\n", "\t- x\n", ":\n", "/**:\n  ros__parameters:\n    seed: [1\n"])
            .prop_map(String::from),
        1 => ".{0,120}",
        1 => prop::collection::vec(any::<u8>(), 0..120).prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
    ]
}

#[test]
fn fuzz_parameter_files() {
    let names = Names::new(&RosArgs { namespace: Some("/plant".into()), ..RosArgs::default() }).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("params.yaml");
    let counts = std::cell::RefCell::new((0u32, 0u32));
    runner()
        .run(&params_file(), |text| {
            std::fs::File::create(&path).unwrap().write_all(text.as_bytes()).unwrap();
            let shown = path.display().to_string();
            match NodeParams::resolve(&NodeArgs::default(), &[], &[&path], &names) {
                Ok(params) => {
                    prop_assert!(params.validate().is_ok());
                    counts.borrow_mut().0 += 1;
                }
                Err(e) => {
                    prop_assert!(e.contains(&shown), "the error does not name the file: {e}\n--- file ---\n{text}");
                    // It names the offending key, or says what is wrong with the file as a whole.
                    let keys =
                        load_params_file(&path, &names).map(|kv| kv.into_iter().map(|(k, _)| k).collect::<Vec<_>>());
                    let names_problem = match &keys {
                        Ok(keys) => keys.iter().any(|k| e.contains(k.as_str())),
                        Err(_) => {
                            ["not valid YAML", "must be a mapping", "ros__parameters", "is not a string", "cannot read"]
                                .iter()
                                .any(|w| e.contains(w))
                        }
                    };
                    prop_assert!(names_problem, "the error does not name the problem: {e}\n--- file ---\n{text}");
                    counts.borrow_mut().1 += 1;
                }
            }
            Ok(())
        })
        .unwrap();
    let (ok, refused) = counts.into_inner();
    eprintln!(
        "fuzz parameter files: {} cases: {ok} accepted (valid), {refused} refused naming the problem",
        ok + refused
    );
}

// ------------------------------------------------------------------------------------------
// --ros-args

fn ros_token() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => select(vec!["-r", "--remap", "-p", "--param", "--params-file", "--log-level", "--enable-rosout-logs",
                         "--disable-stdout-logs", "--", "-e", "--ros-args", "--bogus", "-", ""])
            .prop_map(String::from),
        3 => (prop_oneof!["[a-z_/]{0,8}", select(vec!["__ns", "__node", "__name", "__fancy", "other:__ns", "x:y:z"])
                 .prop_map(String::from)],
              select(vec![":=", "=", ":", ""]), "[a-zA-Z0-9_/.:\\[\\]{}-]{0,10}")
            .prop_map(|(a, op, b)| format!("{a}{op}{b}")),
        2 => (yaml_key(), yaml_scalar()).prop_map(|(k, v)| format!("{k}:={v}")),
        1 => ".{0,16}",
    ]
}

/// Whether an error quotes one of the arguments (or, for `node:name:=value` rules, the rule or name
/// it is about).
fn names_an_argument(e: &str, tokens: &[String]) -> bool {
    tokens.iter().any(|t| {
        if e.contains(&format!("'{t}'")) || (!t.is_empty() && e.contains(t.as_str())) {
            return true;
        }
        let Some((left, right)) = t.split_once(":=") else { return false };
        let name = left.rsplit(':').next().unwrap_or(left);
        e.contains(&format!("{name}:={right}")) || e.contains(&format!("'{name}'"))
    })
}

#[test]
fn fuzz_ros_args() {
    let counts = std::cell::RefCell::new((0u32, 0u32));
    runner()
        .run(&prop::collection::vec(ros_token(), 0..10), |tokens| {
            match RosArgs::parse(&tokens, "sorting_line") {
                Ok(ros) => {
                    // Whatever parsed must also resolve or fail with a message (no panic).
                    if let Ok(names) = Names::new(&ros) {
                        let empty: [&std::path::Path; 0] = [];
                        if let Err(e) = NodeParams::resolve(&NodeArgs::default(), &ros.params, &empty, &names) {
                            prop_assert!(e.contains("parameter"), "{e}");
                        }
                    }
                    counts.borrow_mut().0 += 1;
                }
                Err(e) => {
                    prop_assert!(e.starts_with("--ros-args:"), "{e}");
                    prop_assert!(
                        names_an_argument(&e, &tokens),
                        "the error names none of the arguments {tokens:?}: {e}"
                    );
                    counts.borrow_mut().1 += 1;
                }
            }
            Ok(())
        })
        .unwrap();
    let (ok, refused) = counts.into_inner();
    eprintln!("fuzz --ros-args: {} cases: {ok} parsed, {refused} refused naming the argument", ok + refused);
}
