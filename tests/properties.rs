//! Properties of the line and the rule-based agent that must hold for every configuration, seed
//! and command sequence (proptest), plus one statistical check of the accuracy noise.
//!
//! The expectations here are computed from the dynamics notes (sections 1-3), not by calling the
//! library's own helpers where that would make a check circular: the accuracy band, the reward
//! formula and the sorting arithmetic are restated independently.

use std::sync::OnceLock;

use proptest::prelude::*;
use proptest::sample::select;
use sorting_line::sim::config::{SETUPS, VARIANTS};
use sorting_line::sim::rba::{analysis, AnalysisRow, RbaTable};
use sorting_line::sim::speed::{index_of_speed, SPEED_COUNT};
use sorting_line::sim::{
    Action, Batch, Category, Containers, InputKind, Line, LineConfig, Observation, Setup, SortMode, StepOutcome,
    Variant,
};

/// Tolerance for restated formulas whose operations run in a different order than the library's.
const EPS: f64 = 1e-9;
/// Units in the line right after a reset: input [30, 50], belt [40, 20], machine [75, 25].
const START_UNITS: u64 = 240;
const START_SPEED: usize = 5;

#[derive(Clone, Copy, Debug)]
enum Command {
    Step(Action),
    Reset(Option<u64>),
}

fn action() -> impl Strategy<Value = Action> {
    (0..SPEED_COUNT, 0..3u8).prop_map(|(speed, mode)| Action::new(speed, SortMode::from_index(mode).unwrap()))
}

/// Mostly steps; now and then a reset, with or without a seed.
fn commands(max: usize) -> impl Strategy<Value = Vec<Command>> {
    let command = prop_oneof![
        30 => action().prop_map(Command::Step),
        1 => Just(Command::Reset(None)),
        1 => any::<u64>().prop_map(|s| Command::Reset(Some(s))),
    ];
    prop::collection::vec(command, 0..=max)
}

fn setup_config() -> impl Strategy<Value = LineConfig> {
    (select(SETUPS.to_vec()), select(VARIANTS.to_vec())).prop_map(|(s, v)| LineConfig::for_setup(s, v))
}

fn input_kind() -> impl Strategy<Value = InputKind> {
    select(vec![InputKind::Random, InputKind::Seasonal, InputKind::Seasonal3])
}

/// The paper's setups, and any valid configuration (short episodes exercise truncation).
fn any_config() -> impl Strategy<Value = LineConfig> {
    let custom = (select(VARIANTS.to_vec()), input_kind(), 0.0..=1.0f64, 0.0..=2.0f64, 0.0..0.99f64, 1u32..=80)
        .prop_map(|(variant, input, obs_noise, action_penalty, threshold, max_steps)| LineConfig {
            variant,
            input,
            obs_noise,
            action_penalty,
            threshold,
            max_steps,
        });
    prop_oneof![3 => setup_config(), 2 => custom]
}

/// The line's state before a step, to check what the step did with it.
struct Before {
    input: Batch,
    belt: Batch,
    machine: Batch,
    containers: Containers,
    sorter_accuracy: f64,
    belt_accuracy: f64,
    speed_index: usize,
    step: u32,
}

impl Before {
    fn of(line: &Line) -> Self {
        Before {
            input: line.input(),
            belt: line.belt(),
            machine: line.machine(),
            containers: line.containers(),
            sorter_accuracy: line.sorter_accuracy(),
            belt_accuracy: line.belt_accuracy(),
            speed_index: line.speed_index(),
            step: line.step_count(),
        }
    }
}

/// Accuracy before noise, restated from the notes: base 1 within `1.1 - speed`, else
/// `1 - 3 * excess`; +0.15 matched, -0.10 mismatched; clamped before the noise.
fn noiseless(occupancy: f64, speed_index: usize, matched: Option<bool>) -> f64 {
    let speed = (speed_index + 1) as f64 / 10.0;
    let limit = 1.1 - speed;
    let base = if occupancy <= limit + EPS { 1.0 } else { 1.0 - 3.0 * (occupancy - limit) };
    let effect = match matched {
        None => 0.0,
        Some(true) => 0.15,
        Some(false) => -0.10,
    };
    (base + effect).clamp(0.0, 1.0)
}

fn has_two_decimals(x: f64) -> bool {
    (x * 100.0).round() / 100.0 == x
}

fn check_observation(config: &LineConfig, line: &Line) -> Result<(), TestCaseError> {
    let obs = line.observation();
    let truth = line.input().occupancy();
    prop_assert!((0.0..=1.0).contains(&obs.quantity), "quantity {} outside [0, 1]", obs.quantity);
    prop_assert!(has_two_decimals(obs.quantity), "quantity {} has more than 2 decimals", obs.quantity);
    prop_assert_eq!(obs.category, line.input().category(), "the category is read without noise");
    if config.obs_noise == 0.0 {
        prop_assert_eq!(obs.quantity, truth);
    } else {
        // Relative noise, then rounding: |reading - truth| <= truth * n + 0.005.
        prop_assert!((obs.quantity - truth).abs() <= truth * config.obs_noise + 0.005 + EPS);
    }
    Ok(())
}

fn check_kpis(line: &Line) -> Result<(), TestCaseError> {
    let c = line.containers();
    for (name, v) in [("purity", c.purity()), ("recall_a", c.recall_a()), ("recall_b", c.recall_b())] {
        prop_assert!((0.0..=1.0).contains(&v), "{} = {} outside [0, 1]", name, v);
    }
    if c.total() > 0 {
        prop_assert!((c.purity() - (c.a + c.b) as f64 / c.total() as f64).abs() < EPS);
    }
    prop_assert_eq!(line.entered(), line.accounted(), "material is neither created nor lost");
    Ok(())
}

/// Everything one step must satisfy, given the state before it.
fn check_step(
    config: &LineConfig,
    before: &Before,
    action: Action,
    out: &StepOutcome,
    line: &Line,
) -> Result<(), TestCaseError> {
    // Episode clock: truncated exactly from max_steps on; nothing terminates.
    prop_assert_eq!(out.step, before.step + 1);
    prop_assert_eq!(line.step_count(), out.step);
    prop_assert_eq!(out.truncated, out.step >= config.max_steps);
    prop_assert_eq!(line.truncated(), out.truncated);
    prop_assert!(!out.terminated);

    // Sorting at the sorter's accuracy with truncation, then the line moves one place.
    let sorted = |n: u32| (f64::from(n) * before.sorter_accuracy) as u64;
    let c = line.containers();
    let m = before.machine;
    prop_assert_eq!(c.a - before.containers.a, sorted(m.a));
    prop_assert_eq!(c.b - before.containers.b, sorted(m.b));
    prop_assert_eq!(c.a_false - before.containers.a_false, u64::from(m.a) - sorted(m.a));
    prop_assert_eq!(c.b_false - before.containers.b_false, u64::from(m.b) - sorted(m.b));
    prop_assert_eq!(line.machine(), before.belt);
    prop_assert_eq!(line.belt(), before.input);
    prop_assert_eq!(line.sorter_accuracy(), before.belt_accuracy, "the accuracy travels with its batch");

    // The action as applied: the basic line has no mode; every change of speed is counted.
    let mode = if config.variant == Variant::Basic { SortMode::Basic } else { action.mode };
    prop_assert_eq!(out.action, Action::new(action.speed_index, mode));
    prop_assert_eq!(out.speed_changed, action.speed_index != before.speed_index);

    // Accuracy: the noiseless value minus U(0.10, 0.15), or U(0, 0.05) with a matching mode.
    prop_assert_eq!(out.occupancy, line.belt().occupancy());
    prop_assert!((0.0..=1.0).contains(&out.accuracy), "accuracy {}", out.accuracy);
    let matched = (config.variant == Variant::Advanced).then(|| mode.index() == line.belt().category().index());
    let c0 = noiseless(out.occupancy, action.speed_index, matched);
    let (low, high) = if matched == Some(true) { (0.0, 0.05) } else { (0.10, 0.15) };
    let band = ((c0 - high).clamp(0.0, 1.0) - EPS, (c0 - low).clamp(0.0, 1.0) + EPS);
    prop_assert!(
        band.0 <= out.accuracy && out.accuracy <= band.1,
        "accuracy {} outside {:?} (noiseless {}, matched {:?})",
        out.accuracy,
        band,
        c0,
        matched
    );

    // Reward: flat -0.1 below the threshold (no penalty); otherwise the weighted sum.
    let thr = config.threshold;
    if out.accuracy < thr {
        prop_assert_eq!(out.reward, -0.1);
    } else {
        let accuracy_term = 0.5 * (out.accuracy - thr) / (1.0 - thr);
        let speed_term = 0.5 * (action.speed() - 0.1) / 0.9;
        let penalty = if out.speed_changed { config.action_penalty } else { 0.0 };
        prop_assert!((-EPS..=0.5 + EPS).contains(&accuracy_term));
        prop_assert!((out.reward - (accuracy_term + speed_term - penalty)).abs() < EPS);
        prop_assert!(out.reward <= 1.0 && out.reward >= -penalty, "reward {}", out.reward);
    }
    prop_assert_eq!(out.observation, line.observation());
    check_observation(config, line)?;
    check_kpis(line)
}

fn check_reset(config: &LineConfig, line: &Line, episode_before: u32) -> Result<(), TestCaseError> {
    prop_assert_eq!(line.episode(), episode_before + 1);
    prop_assert_eq!(line.step_count(), 0);
    prop_assert!(!line.truncated());
    prop_assert_eq!(
        (line.input(), line.belt(), line.machine()),
        (Batch::new(30, 50), Batch::new(40, 20), Batch::new(75, 25))
    );
    prop_assert_eq!(line.containers(), Containers::default());
    prop_assert_eq!((line.speed_index(), line.mode()), (START_SPEED, SortMode::Basic));
    prop_assert_eq!((line.sorter_accuracy(), line.belt_accuracy()), (0.75, 0.75));
    prop_assert_eq!(line.entered(), START_UNITS);
    check_observation(config, line)?;
    check_kpis(line)
}

/// What a run produced, for comparing runs.
#[derive(Debug, PartialEq)]
enum Event {
    Step(StepOutcome),
    Reset(Observation),
}

fn apply(line: &mut Line, command: Command) -> Event {
    match command {
        Command::Step(a) => Event::Step(line.step(a)),
        Command::Reset(seed) => Event::Reset(line.reset(seed)),
    }
}

fn run(config: &LineConfig, seed: u64, commands: &[Command]) -> Vec<Event> {
    let mut line = Line::new(config.clone(), seed);
    commands.iter().map(|&c| apply(&mut line, c)).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Every invariant of a step and of a reset, along arbitrary runs.
    #[test]
    fn every_step_and_reset_keeps_the_invariants(
        config in any_config(),
        seed in any::<u64>(),
        commands in commands(200),
    ) {
        let mut line = Line::new(config.clone(), seed);
        prop_assert_eq!(line.episode(), 0);
        check_observation(&config, &line)?;
        check_kpis(&line)?;
        for command in commands {
            match command {
                Command::Step(action) => {
                    let before = Before::of(&line);
                    let out = line.step(action);
                    check_step(&config, &before, action, &out, &line)?;
                }
                Command::Reset(seed) => {
                    let episode = line.episode();
                    line.reset(seed);
                    check_reset(&config, &line, episode)?;
                }
            }
        }
    }

    /// Same seed and commands, same run; a line with another seed stepped in between (and its
    /// resets) changes nothing, because no line shares a random stream with another.
    #[test]
    fn runs_are_deterministic_and_lines_independent(
        config in any_config(),
        seed in any::<u64>(),
        other_seed in any::<u64>(),
        commands in commands(200),
    ) {
        prop_assume!(seed != other_seed);
        let alone = run(&config, seed, &commands);
        let mut line = Line::new(config.clone(), seed);
        let mut other = Line::new(config.clone(), other_seed);
        let mut interleaved = Vec::new();
        for &command in &commands {
            apply(&mut other, command);
            interleaved.push(apply(&mut line, command));
            apply(&mut other, Command::Step(Action::new(9, SortMode::Negative)));
        }
        prop_assert_eq!(&alone, &interleaved);
        prop_assert_eq!(&alone, &run(&config, seed, &commands));
    }

    /// A seeded reset is a fresh line with that seed (only the episode number differs).
    #[test]
    fn seeded_reset_equals_a_new_line(
        config in any_config(),
        seed in any::<u64>(),
        reseed in any::<u64>(),
        before in commands(60),
        after in commands(60),
    ) {
        let mut line = Line::new(config.clone(), seed);
        for &c in &before {
            apply(&mut line, c);
        }
        let mut fresh = Line::new(config.clone(), reseed);
        prop_assert_eq!(line.reset(Some(reseed)), fresh.observation());
        for &c in &after {
            prop_assert_eq!(apply(&mut line, c), apply(&mut fresh, c));
        }
    }

    /// The input stream is the line's own: whatever the agent does, one seed feeds the same batches.
    #[test]
    fn input_does_not_depend_on_actions(
        config in any_config(),
        seed in any::<u64>(),
        actions in prop::collection::vec((action(), action()), 0..=200),
    ) {
        let mut one = Line::new(config.clone(), seed);
        let mut two = Line::new(config, seed);
        for (a, b) in actions {
            one.step(a);
            two.step(b);
            prop_assert_eq!(one.input(), two.input());
        }
    }

    /// The agents only ever answer with actions of the line's action space.
    #[test]
    fn rba_actions_are_always_in_range(
        table in 0..SETUPS.len() * VARIANTS.len(),
        quantity in prop_oneof![0.0..=1.0f64, any::<f64>()],
        category in select(vec![Category::Basic, Category::Positive, Category::Negative]),
        current in 0..SPEED_COUNT,
    ) {
        let (config, table) = &setup_tables()[table];
        let obs = Observation { quantity, category };
        for action in [table.decide(obs), table.decide_holding(obs, current)] {
            prop_assert!(action.speed_index < SPEED_COUNT);
            if config.variant == Variant::Basic {
                prop_assert_eq!(action.mode, SortMode::Basic);
            }
            prop_assert_eq!(Action::from_discrete(config.variant, action.to_discrete(config.variant)), Some(action));
        }
    }

    /// With a noise-free sensor the table's decision is the analytic argmax, at any threshold.
    #[test]
    fn rba_is_the_argmax_without_sensor_noise_at_any_threshold(
        variant in select(VARIANTS.to_vec()),
        input in input_kind(),
        threshold in 0.0..0.99f64,
        action_penalty in 0.0..=2.0f64,
    ) {
        let config = LineConfig { variant, input, threshold, action_penalty, obs_noise: 0.0, ..LineConfig::default() };
        if let Err(message) = rba_matches_analysis(&config) {
            return Err(TestCaseError::fail(message));
        }
    }
}

/// Tables of the eight paper configurations, built once: building one takes milliseconds.
fn setup_tables() -> &'static [(LineConfig, RbaTable)] {
    static TABLES: OnceLock<Vec<(LineConfig, RbaTable)>> = OnceLock::new();
    TABLES.get_or_init(|| {
        SETUPS
            .iter()
            .flat_map(|&s| VARIANTS.iter().map(move |&v| LineConfig::for_setup(s, v)))
            .map(|c| {
                let table = RbaTable::build(&c);
                (c, table)
            })
            .collect()
    })
}

/// The cells of the analysis: its rows grouped by (occupancy, category), in order.
fn cells(rows: &[AnalysisRow]) -> Vec<&[AnalysisRow]> {
    rows.chunk_by(|x, y| x.occupancy == y.occupancy && x.category == y.category).collect()
}

/// `RbaTable::decide` against the row marked `best` in every cell, which must also be the
/// highest expected reward of its cell (ties to the first, i.e. slowest, option).
fn rba_matches_analysis(config: &LineConfig) -> Result<(), String> {
    let table = RbaTable::build(config);
    let rows = analysis(config);
    let options = Action::count(config.variant);
    for cell in cells(&rows) {
        let here = format!("{config:?}, occupancy {}, category {:?}", cell[0].occupancy, cell[0].category);
        if cell.len() != options {
            return Err(format!("{here}: {} rows, expected {options}", cell.len()));
        }
        let best: Vec<&AnalysisRow> = cell.iter().filter(|r| r.best).collect();
        let [best] = best[..] else { return Err(format!("{here}: {} rows marked best", best.len())) };
        let first_max = cell.iter().fold(&cell[0], |m, r| if r.expected_reward > m.expected_reward { r } else { m });
        if !std::ptr::eq(best, first_max) {
            return Err(format!("{here}: best {best:?} is not the first maximum {first_max:?}"));
        }
        let want = Action::new(index_of_speed(best.speed).expect("a belt speed"), best.mode);
        // The basic line has no ratio sensor: its decision must not depend on the category.
        let categories: &[Category] = match config.variant {
            Variant::Basic => &[Category::Basic, Category::Positive, Category::Negative],
            Variant::Advanced => std::slice::from_ref(&best.category),
        };
        for &category in categories {
            let got = table.decide(Observation { quantity: best.occupancy, category });
            if got != want {
                return Err(format!("{here} (observed as {category:?}): decide = {got:?}, analysis best = {want:?}"));
            }
        }
    }
    Ok(())
}

/// The analysis at the paper's settings (setups A and B have a noise-free sensor).
#[test]
fn rba_is_the_analytic_argmax_for_the_noise_free_setups() {
    for setup in [Setup::A, Setup::B] {
        for variant in VARIANTS {
            rba_matches_analysis(&LineConfig::for_setup(setup, variant)).unwrap();
        }
    }
}

/// The analysis's expected reward, checked against a direct numerical average of the reward
/// formula over the accuracy noise (midpoint rule; the threshold jump costs ~1/n of accuracy).
#[test]
fn analytic_expected_reward_matches_numerical_integration() {
    const N: usize = 4000;
    for variant in VARIANTS {
        let config = LineConfig::for_setup(Setup::A, variant);
        let thr = config.threshold;
        for row in analysis(&config) {
            let speed_index = index_of_speed(row.speed).unwrap();
            let matched = (variant == Variant::Advanced).then(|| row.mode.index() == row.category.index());
            let c0 = noiseless(row.occupancy, speed_index, matched);
            let (low, high) = if matched == Some(true) { (0.0, 0.05) } else { (0.10, 0.15) };
            let mean: f64 = (0..N)
                .map(|i| {
                    let accuracy = (c0 - (low + (high - low) * (i as f64 + 0.5) / N as f64)).clamp(0.0, 1.0);
                    if accuracy < thr {
                        -0.1
                    } else {
                        0.5 * (accuracy - thr) / (1.0 - thr) + 0.5 * (row.speed - 0.1) / 0.9
                    }
                })
                .sum::<f64>()
                / N as f64;
            assert!((row.expected_reward - mean).abs() < 1e-3, "{row:?}: numerical {mean}");
            assert!((row.noiseless_accuracy - c0).abs() < EPS, "{row:?}: restated {c0}");
        }
    }
}

/// At speed 0.1 no batch exceeds the limit (1.0), so accuracy = 1 - U(0.10, 0.15): mean 0.875.
/// An added noise would clamp every accuracy to 1.0; a centred one would reach above 0.9.
#[test]
fn accuracy_noise_is_subtracted() {
    const STEPS: usize = 2000;
    let mut line = Line::new(LineConfig::for_setup(Setup::A, Variant::Basic), 2024);
    let mut sum = 0.0;
    for k in 0..STEPS {
        if k > 0 && k % 50 == 0 {
            line.reset(None);
        }
        let out = line.step(Action::new(0, SortMode::Basic));
        assert!((0.85..=0.9).contains(&out.accuracy), "step {k}: accuracy {}", out.accuracy);
        sum += out.accuracy;
    }
    let mean = sum / STEPS as f64;
    // The standard error is 0.05 / sqrt(12 * 2000) = 0.0003: 0.005 is over 15 of them.
    assert!((mean - 0.875).abs() < 0.005, "mean accuracy {mean}");
}
