//! One sorting line: input sensor, conveyor belt, sorting machine and containers, stepped one
//! tick at a time. This is the reference environment's dynamics, number for number, with the
//! defects listed in the dynamics notes (section 0) fixed: per-line seeded streams, truncation
//! instead of termination, and the KPIs reported every step.
//!
//! # One step, in order
//! 1. **Sort** the batch in the sorting machine at the sorter's accuracy: correct = floor(n * acc)
//!    per material, the rest goes to the wrong container.
//! 2. **Advance**: machine <- belt, belt <- input, input <- a new batch (input stream), and the
//!    accuracy computed for the belt batch last step travels with it to the sorter.
//! 3. **Set the speed** (and the mode) from the action; a change of speed is counted.
//! 4. **Accuracy** of the batch now on the belt (the one the last observation described):
//!    noise stream draw 1 = U(0.10, 0.15); with a matching mode, draw 2 = U(0, 0.05) replaces it
//!    (both draws are consumed, as in the reference).
//! 5. **Reward** from that accuracy, the speed and the switching penalty.
//! 6. **Observe** the new input batch: noise stream draw = U(-n, n) (drawn even when n = 0),
//!    reading = round2(clamp(q + q * u, 0, 1)).
//! 7. step += 1; `truncated` once step >= max_steps. `terminated` is never set.
//!
//! A reset draws one observation-noise value (for the fixed first input batch) and nothing else.
//!
//! # Evolution
//! A line may carry an evolution schedule (`evolution.rs`): events due at a tick apply before
//! step 1 of that tick, events due at an episode at its reset before the seed is used. The
//! line's hardware (sort modes, ratio sensor) starts as its variant has it. With the empty
//! schedule the line is exactly the line without one (the golden trajectories pin this).

use serde::{Deserialize, Serialize};

use super::accuracy::{noiseless_accuracy, with_noise, ModeEffect, START_ACCURACY};
use super::config::{LineConfig, Variant};
use super::evolution::{ActiveFault, At, Event, Schedule, Settings, Timeline};
use super::input::InputGenerator;
use super::material::{Batch, Category, SortMode, SORT_MODES};
use super::reward::reward;
use super::rng::{stream, uniform, SimRng, Stream};
use super::round::round2;
use super::speed::{SPEEDS, SPEED_COUNT, START_SPEED_INDEX};

/// The fixed contents of the line after a reset: input, belt, sorting machine.
pub const START_INPUT: Batch = Batch::new(30, 50);
pub const START_BELT: Batch = Batch::new(40, 20);
pub const START_MACHINE: Batch = Batch::new(75, 25);

/// What the agent commands for one tick. Decoding checks the speed index like [`Action::new`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "RawAction")]
pub struct Action {
    /// 0..=9, speed (i + 1) / 10.
    pub speed_index: usize,
    /// Ignored by the basic line.
    pub mode: SortMode,
}

/// An action as decoded, before its range check.
#[derive(Deserialize)]
struct RawAction {
    speed_index: usize,
    #[serde(default)]
    mode: SortMode,
}

impl TryFrom<RawAction> for Action {
    type Error = String;
    fn try_from(raw: RawAction) -> Result<Self, String> {
        if raw.speed_index < SPEED_COUNT {
            Ok(Action { speed_index: raw.speed_index, mode: raw.mode })
        } else {
            Err(format!("speed_index = {} is out of range: allowed 0..={}", raw.speed_index, SPEED_COUNT - 1))
        }
    }
}

impl Action {
    pub fn new(speed_index: usize, mode: SortMode) -> Self {
        assert!(speed_index < SPEED_COUNT, "speed index {speed_index} out of 0..={}", SPEED_COUNT - 1);
        Action { speed_index, mode }
    }

    /// How many Gymnasium actions a line whose actions decode as `variant` has: the ten speeds,
    /// times the three sort modes on the advanced line. The one count every action space, mask,
    /// random agent and range check of the crate and the extension is sized by.
    pub const fn count(variant: Variant) -> usize {
        match variant {
            Variant::Basic => SPEED_COUNT,
            Variant::Advanced => SPEED_COUNT * SORT_MODES.len(),
        }
    }

    /// Decodes a Gymnasium action: basic `speed_index`, advanced `speed_index * 3 + mode`.
    pub fn from_discrete(variant: Variant, action: usize) -> Option<Self> {
        let modes = SORT_MODES.len();
        (action < Action::count(variant)).then(|| match variant {
            Variant::Basic => Action::new(action, SortMode::Basic),
            Variant::Advanced => Action::new(action / modes, SORT_MODES[action % modes]),
        })
    }

    pub fn to_discrete(self, variant: Variant) -> usize {
        match variant {
            Variant::Basic => self.speed_index,
            Variant::Advanced => self.speed_index * SORT_MODES.len() + self.mode.index(),
        }
    }

    pub fn speed(self) -> f64 {
        SPEEDS[self.speed_index]
    }
}

/// Whether a line takes sort mode `mode` now: any mode while it has sort modes, only mode 0
/// (basic) without (an evolving line before its upgrade). The one mask rule: [`Line::mode_allowed`]
/// checks commands with it, and [`action_mask`] masks Gymnasium actions with it.
pub fn mode_allowed(sort_modes: bool, mode: SortMode) -> bool {
    sort_modes || mode == SortMode::Basic
}

/// Which Gymnasium actions of `variant`'s encoding a line with (or without) sort modes takes,
/// action 0 first: [`mode_allowed`] of each action's mode (every basic action has mode 0).
pub fn action_mask(variant: Variant, sort_modes: bool) -> impl Iterator<Item = bool> {
    (0..Action::count(variant))
        .map(move |a| Action::from_discrete(variant, a).is_some_and(|action| mode_allowed(sort_modes, action.mode)))
}

/// What the agent sees: the noisy input reading and (advanced) the exact ratio category.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    /// Noisy amount of the next batch, 0..=1, two decimals.
    pub quantity: f64,
    /// Ratio category of the next batch (noise-free; the basic line does not show it).
    pub category: Category,
}

/// The four container counters, in material units.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Containers {
    pub a: u64,
    pub a_false: u64,
    pub b: u64,
    pub b_false: u64,
}

impl Containers {
    pub fn total(&self) -> u64 {
        self.a + self.a_false + self.b + self.b_false
    }

    /// The real purity of what was sorted: correctly sorted / all sorted (0 when empty).
    pub fn purity(&self) -> f64 {
        ratio_or_zero(self.a + self.b, self.total())
    }

    /// Share of material A that was sorted correctly (the reference dashboard's "A %").
    pub fn recall_a(&self) -> f64 {
        ratio_or_zero(self.a, self.a + self.a_false)
    }

    /// Share of material B that was sorted correctly.
    pub fn recall_b(&self) -> f64 {
        ratio_or_zero(self.b, self.b + self.b_false)
    }
}

fn ratio_or_zero(num: u64, den: u64) -> f64 {
    if den == 0 {
        0.0
    } else {
        num as f64 / den as f64
    }
}

/// The result of one step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepOutcome {
    /// Steps taken in this episode, this one included.
    pub step: u32,
    pub action: Action,
    /// Accuracy set for the batch on the belt (sorted at the next step).
    pub accuracy: f64,
    /// Occupancy of the batch on the belt.
    pub occupancy: f64,
    pub reward: f64,
    pub speed_changed: bool,
    pub observation: Observation,
    /// Always false: nothing ends an episode but the time limit.
    pub terminated: bool,
    /// The time limit was reached.
    pub truncated: bool,
}

/// A sorting line with its own random streams.
#[derive(Clone, Debug)]
pub struct Line {
    config: LineConfig,
    seed: u64,
    episode: u32,
    step: u32,
    generator: InputGenerator,
    noise: SimRng,
    input: Batch,
    belt: Batch,
    machine: Batch,
    belt_accuracy: f64,
    sorter_accuracy: f64,
    speed_index: usize,
    mode: SortMode,
    containers: Containers,
    observation: Observation,
    cumulative_reward: f64,
    speed_changes: u32,
    last: Option<StepOutcome>,
    /// Units that entered the line this episode (start contents included): for conservation checks.
    entered: u64,
    /// Steps taken since the line was built, over all episodes.
    tick: u64,
    /// The machine upgrade: whether the sorting machine has modes.
    sort_modes: bool,
    /// The sensor upgrade: whether the ratio sensor is fitted.
    ratio_sensor: bool,
    /// The input-sensor fault in progress.
    fault: Option<ActiveFault>,
    timeline: Timeline,
    /// `timeline.due_tick()`, kept at hand: the only evolution cost of a step without events.
    due_tick: u64,
}

impl Line {
    /// A line seeded with `seed`, already reset (episode 0).
    ///
    /// # Panics
    /// If the configuration is invalid: validate configurations from users first.
    pub fn new(config: LineConfig, seed: u64) -> Self {
        Self::with_evolution(config, seed, Schedule::default())
    }

    /// A line seeded with `seed` that evolves by `schedule`, already reset (episode 0, with the
    /// schedule's episode-0 events applied: it starts like a new line of the setup they make).
    ///
    /// # Panics
    /// If the configuration or the schedule is invalid: validate those from users first.
    pub fn with_evolution(config: LineConfig, seed: u64, schedule: Schedule) -> Self {
        config.validate().expect("a valid line configuration");
        schedule.validate().expect("a valid evolution schedule");
        let advanced = config.variant == Variant::Advanced;
        let timeline = Timeline::new(schedule);
        let mut line = Line {
            generator: InputGenerator::new(config.input, seed),
            noise: stream(seed, Stream::Noise),
            config,
            seed,
            episode: 0,
            step: 0,
            input: START_INPUT,
            belt: START_BELT,
            machine: START_MACHINE,
            belt_accuracy: START_ACCURACY,
            sorter_accuracy: START_ACCURACY,
            speed_index: START_SPEED_INDEX,
            mode: SortMode::Basic,
            containers: Containers::default(),
            observation: Observation { quantity: 0.0, category: Category::Basic },
            cumulative_reward: 0.0,
            speed_changes: 0,
            last: None,
            entered: 0,
            tick: 0,
            sort_modes: advanced,
            ratio_sensor: advanced,
            fault: None,
            due_tick: timeline.due_tick(),
            timeline,
        };
        let initial_input = line.config.input;
        line.apply_episode_events();
        if line.config.input != initial_input {
            // As if built with that input: the generator starts from the seed.
            line.generator.reseed(seed);
        }
        line.restart();
        line
    }

    /// Starts a new episode. With a seed, both streams restart from it; without one they carry
    /// on, so a run of several episodes is reproduced by its first seed.
    pub fn reset(&mut self, seed: Option<u64>) -> Observation {
        self.episode += 1;
        self.apply_episode_events();
        if let Some(seed) = seed {
            self.seed = seed;
            self.generator.reseed(seed);
            self.noise = stream(seed, Stream::Noise);
        }
        self.restart()
    }

    fn apply_episode_events(&mut self) {
        for event in self.timeline.take_due_at_episode(self.episode) {
            self.apply(&event);
        }
    }

    #[cold]
    fn apply_tick_events(&mut self) {
        for event in self.timeline.take_due_at_tick(self.tick) {
            self.apply(&event);
        }
        self.due_tick = self.timeline.due_tick();
    }

    /// Applies one event's changes (no random draws: see the evolution module's stream rules).
    fn apply(&mut self, event: &Event) {
        if let Some(v) = event.obs_noise {
            self.config.obs_noise = v;
        }
        if let Some(v) = event.action_penalty {
            self.config.action_penalty = v;
        }
        if let Some(v) = event.threshold {
            self.config.threshold = v;
        }
        if let Some(kind) = event.input {
            if kind != self.config.input {
                self.config.input = kind;
                self.generator.switch(kind);
            }
        }
        if let Some(on) = event.sort_modes {
            self.sort_modes = on;
        }
        if let Some(on) = event.ratio_sensor {
            self.ratio_sensor = on;
        }
        if let Some(fault) = event.input_fault {
            let stuck_at = self.observation.quantity;
            self.fault = Some(ActiveFault { kind: fault.kind, remaining: fault.ticks, stuck_at });
        }
    }

    fn restart(&mut self) -> Observation {
        self.step = 0;
        self.input = START_INPUT;
        self.belt = START_BELT;
        self.machine = START_MACHINE;
        self.belt_accuracy = START_ACCURACY;
        self.sorter_accuracy = START_ACCURACY;
        self.speed_index = START_SPEED_INDEX;
        self.mode = SortMode::Basic;
        self.containers = Containers::default();
        self.cumulative_reward = 0.0;
        self.speed_changes = 0;
        self.last = None;
        self.entered = u64::from(START_INPUT.total() + START_BELT.total() + START_MACHINE.total());
        self.observation = self.observe();
        self.observation
    }

    /// Advances the line one tick (see the module docs for the exact order).
    ///
    /// # Panics
    /// If `action.speed_index` is out of 0..=9 (only possible by building an `Action` literal:
    /// [`Action::new`] and decoding check it). The check comes first, so the line is never left
    /// half-stepped.
    pub fn step(&mut self, action: Action) -> StepOutcome {
        assert!(action.speed_index < SPEED_COUNT, "speed index {} out of 0..={}", action.speed_index, SPEED_COUNT - 1);
        if self.tick == self.due_tick {
            self.apply_tick_events();
        }
        // 1. Sort the machine's batch.
        let correct_a = (f64::from(self.machine.a) * self.sorter_accuracy) as u32;
        let correct_b = (f64::from(self.machine.b) * self.sorter_accuracy) as u32;
        self.containers.a += u64::from(correct_a);
        self.containers.b += u64::from(correct_b);
        self.containers.a_false += u64::from(self.machine.a - correct_a);
        self.containers.b_false += u64::from(self.machine.b - correct_b);

        // 2. Advance the line.
        self.machine = self.belt;
        self.belt = self.input;
        self.input = self.generator.next_batch();
        self.entered += u64::from(self.input.total());
        self.sorter_accuracy = self.belt_accuracy;

        // 3. Set speed and mode.
        let speed_changed = action.speed_index != self.speed_index;
        self.speed_index = action.speed_index;
        self.mode = if self.sort_modes { action.mode } else { SortMode::Basic };
        self.speed_changes += u32::from(speed_changed);

        // 4. Accuracy of the belt batch.
        let effect = self.mode_effect();
        let occupancy = self.belt.occupancy();
        let noiseless = noiseless_accuracy(occupancy, self.speed_index, effect);
        let mut noise = uniform(&mut self.noise, super::accuracy::NOISE.0, super::accuracy::NOISE.1);
        if effect == ModeEffect::Matched {
            let (low, high) = super::accuracy::MATCHED_NOISE;
            noise = uniform(&mut self.noise, low, high);
        }
        self.belt_accuracy = with_noise(noiseless, noise);

        // 5. Reward.
        let penalty = if speed_changed { self.config.action_penalty } else { 0.0 };
        let reward = reward(self.belt_accuracy, self.config.threshold, self.speed_index, penalty);
        self.cumulative_reward += reward;

        // 6. Observe the new input; 7. count the step.
        self.observation = self.observe();
        if let Some(fault) = &mut self.fault {
            fault.remaining -= 1;
            if fault.remaining == 0 {
                self.fault = None;
            }
        }
        self.step += 1;
        self.tick += 1;
        let outcome = StepOutcome {
            step: self.step,
            action: Action { speed_index: self.speed_index, mode: self.mode },
            accuracy: self.belt_accuracy,
            occupancy,
            reward,
            speed_changed,
            observation: self.observation,
            terminated: false,
            truncated: self.step >= self.config.max_steps,
        };
        self.last = Some(outcome);
        outcome
    }

    fn mode_effect(&self) -> ModeEffect {
        // A machine without sort modes (the basic line, or an advanced one before its upgrade)
        // sorts every batch as the basic line does.
        let machine = if self.sort_modes { Variant::Advanced } else { Variant::Basic };
        ModeEffect::of(machine, self.mode, self.belt.category())
    }

    /// Reads the input sensor (one noise-stream draw, taken even when a fault replaces the
    /// reading, so that a fault shifts no stream).
    fn observe(&mut self) -> Observation {
        let amount = self.input.occupancy();
        let n = self.config.obs_noise;
        let u = uniform(&mut self.noise, -n, n);
        let mut quantity = round2((amount + amount * u).clamp(0.0, 1.0));
        if let Some(fault) = &self.fault {
            quantity = fault.reading();
        }
        Observation { quantity, category: self.input.category() }
    }

    /// The configuration now: the one the line was built with, as its evolution events changed
    /// it (`variant` stays the built one: see [`Line::sort_modes`] and [`Line::ratio_sensor`]).
    pub fn config(&self) -> &LineConfig {
        &self.config
    }
    /// The line's evolution schedule (empty for a line that does not evolve).
    pub fn evolution(&self) -> &Schedule {
        self.timeline.schedule()
    }
    /// Steps taken since the line was built, over all episodes: the next step is this tick.
    pub fn tick(&self) -> u64 {
        self.tick
    }
    /// Whether the sorting machine has its modes (advanced variant, or the machine upgrade).
    pub fn sort_modes(&self) -> bool {
        self.sort_modes
    }
    /// Whether the ratio sensor is fitted (advanced variant, or the sensor upgrade).
    pub fn ratio_sensor(&self) -> bool {
        self.ratio_sensor
    }
    /// What the ratio sensor reads of the next batch: its category, or `None` (unknown) while
    /// the line has no ratio sensor.
    pub fn category_reading(&self) -> Option<Category> {
        self.ratio_sensor.then_some(self.observation.category)
    }
    /// The events due at the start of the next step (tick [`Line::tick`]) that have not applied
    /// yet, with their indices in the schedule, and the line's settings once they have. `None`
    /// when no event is due there. A host announces them when the line arrives at that tick, so
    /// a client knows before it commands the step (the line applies them inside [`Line::step`]).
    pub fn pending_tick_events(&self) -> Option<(Vec<usize>, Settings)> {
        if self.tick != self.due_tick {
            return None;
        }
        let indices = self.timeline.schedule().events_at(At::Tick(self.tick)).map(|(i, _)| i).collect();
        let mut after = self.clone();
        after.apply_tick_events();
        Some((indices, after.settings()))
    }
    /// Whether the next step runs with sort modes: [`Line::sort_modes`], unless an event due at
    /// the start of that step switches them (what a host checks a mode command against).
    pub fn sort_modes_at_next_step(&self) -> bool {
        if self.tick != self.due_tick {
            return self.sort_modes;
        }
        let due = self.timeline.schedule().events_at(At::Tick(self.tick));
        due.filter_map(|(_, e)| e.sort_modes).last().unwrap_or(self.sort_modes)
    }
    /// Whether `mode` is a valid command now: any mode with sort modes, only mode 0 without.
    pub fn mode_allowed(&self, mode: SortMode) -> bool {
        mode_allowed(self.sort_modes, mode)
    }
    /// The valid actions of the advanced action space (`speed_index * 3 + mode`) now.
    pub fn action_mask(&self) -> [bool; Action::count(Variant::Advanced)] {
        let mut mask = [false; Action::count(Variant::Advanced)];
        for (m, allowed) in mask.iter_mut().zip(action_mask(Variant::Advanced, self.sort_modes)) {
            *m = allowed;
        }
        mask
    }
    /// Everything events can change, as it is now.
    pub fn settings(&self) -> Settings {
        Settings {
            obs_noise: self.config.obs_noise,
            action_penalty: self.config.action_penalty,
            threshold: self.config.threshold,
            input: self.config.input,
            sort_modes: self.sort_modes,
            ratio_sensor: self.ratio_sensor,
            input_fault: self.fault,
        }
    }
    /// The seed the current streams started from.
    pub fn seed(&self) -> u64 {
        self.seed
    }
    /// Episodes started since the line was built (0 for the first).
    pub fn episode(&self) -> u32 {
        self.episode
    }
    /// Steps taken in this episode.
    pub fn step_count(&self) -> u32 {
        self.step
    }
    /// Whether this episode has reached its time limit.
    pub fn truncated(&self) -> bool {
        self.step >= self.config.max_steps
    }
    pub fn observation(&self) -> Observation {
        self.observation
    }
    pub fn input(&self) -> Batch {
        self.input
    }
    pub fn belt(&self) -> Batch {
        self.belt
    }
    pub fn machine(&self) -> Batch {
        self.machine
    }
    pub fn containers(&self) -> Containers {
        self.containers
    }
    pub fn belt_accuracy(&self) -> f64 {
        self.belt_accuracy
    }
    pub fn sorter_accuracy(&self) -> f64 {
        self.sorter_accuracy
    }
    pub fn speed_index(&self) -> usize {
        self.speed_index
    }
    pub fn speed(&self) -> f64 {
        SPEEDS[self.speed_index]
    }
    pub fn mode(&self) -> SortMode {
        self.mode
    }
    pub fn cumulative_reward(&self) -> f64 {
        self.cumulative_reward
    }
    pub fn speed_changes(&self) -> u32 {
        self.speed_changes
    }
    pub fn last_step(&self) -> Option<&StepOutcome> {
        self.last.as_ref()
    }
    /// Units that entered this episode, the start contents included.
    pub fn entered(&self) -> u64 {
        self.entered
    }
    /// Units now in the line or its containers; always equal to [`Line::entered`].
    pub fn accounted(&self) -> u64 {
        u64::from(self.input.total() + self.belt.total() + self.machine.total()) + self.containers.total()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::config::{Setup, SETUPS, VARIANTS};

    #[test]
    fn first_step_sorts_the_start_batch_at_075() {
        let mut line = Line::new(LineConfig::for_setup(Setup::A, Variant::Basic), 1);
        assert_eq!(line.observation().quantity, 0.8); // [30, 50], no noise in setup A
        let out = line.step(Action::new(5, SortMode::Basic));
        // [75, 25] at 0.75: 56 + 18 correct, 19 + 7 wrong.
        assert_eq!(line.containers(), Containers { a: 56, a_false: 19, b: 18, b_false: 7 });
        assert_eq!(line.belt(), START_INPUT);
        assert_eq!(line.machine(), START_BELT);
        assert!(!out.speed_changed, "0.6 is the start speed");
        // Belt occupancy 0.8 at speed 0.6 (limit 0.5): base 0.1 -> accuracy 0, reward -0.1.
        assert_eq!(out.accuracy, 0.0);
        assert_eq!(out.reward, -0.1);
    }

    #[test]
    fn episode_is_truncated_never_terminated() {
        let mut line = Line::new(LineConfig::for_setup(Setup::B, Variant::Advanced), 9);
        for k in 1..=50 {
            let out = line.step(Action::new(k % 10, SortMode::Positive));
            assert!(!out.terminated);
            assert_eq!(out.truncated, k == 50);
        }
    }

    #[test]
    fn same_seed_same_trajectory_and_lines_do_not_interfere() {
        for setup in SETUPS {
            for variant in VARIANTS {
                let config = LineConfig::for_setup(setup, variant);
                let mut alone = Line::new(config.clone(), 42);
                let mut twin = Line::new(config.clone(), 42);
                let mut other = Line::new(config, 43);
                for k in 0..200 {
                    let action = Action::new((k * 7) % 10, SortMode::from_index((k % 3) as u8).unwrap());
                    other.step(action);
                    let a = alone.step(action);
                    other.step(action);
                    assert_eq!(a, twin.step(action));
                }
            }
        }
    }

    #[test]
    fn reset_without_seed_continues_the_streams() {
        let config = LineConfig::for_setup(Setup::D, Variant::Basic);
        let mut generator = crate::sim::input::InputGenerator::new(config.input, 5);
        let batches: Vec<Batch> = (0..11).map(|_| generator.next_batch()).collect();
        let mut line = Line::new(config.clone(), 5);
        for _ in 0..10 {
            line.step(Action::new(3, SortMode::Basic));
        }
        line.reset(None);
        assert_eq!((line.episode(), line.step_count(), line.input()), (1, 0, START_INPUT));
        line.step(Action::new(3, SortMode::Basic));
        assert_eq!(line.input(), batches[10], "the input stream carried on");
        // A seeded reset repeats episode 0 exactly.
        let mut fresh = Line::new(config, 5);
        assert_eq!(line.reset(Some(5)), fresh.observation());
        for k in 0..20 {
            assert_eq!(
                line.step(Action::new(k % 10, SortMode::Basic)),
                fresh.step(Action::new(k % 10, SortMode::Basic))
            );
        }
    }

    #[test]
    fn out_of_range_actions_are_refused_when_decoded_and_before_stepping() {
        let err = serde_json::from_str::<Action>(r#"{"speed_index": 12, "mode": "basic"}"#).unwrap_err();
        assert!(err.to_string().contains("speed_index = 12 is out of range: allowed 0..=9"), "{err}");
        let ok: Action = serde_json::from_str(r#"{"speed_index": 9, "mode": "negative"}"#).unwrap();
        assert_eq!(ok, Action::new(9, SortMode::Negative));
        let mut line = Line::new(LineConfig::default(), 1);
        let bad = Action { speed_index: 10, mode: SortMode::Basic };
        let stepped = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| line.step(bad)));
        assert!(stepped.is_err());
        assert_eq!((line.step_count(), line.speed_index(), line.machine()), (0, START_SPEED_INDEX, START_MACHINE));
    }

    #[test]
    fn discrete_actions_round_trip() {
        for a in 0..30 {
            let act = Action::from_discrete(Variant::Advanced, a).unwrap();
            assert_eq!(act.to_discrete(Variant::Advanced), a);
        }
        assert_eq!(Action::from_discrete(Variant::Advanced, 17), Some(Action::new(5, SortMode::Negative)));
        assert_eq!(Action::from_discrete(Variant::Basic, 10), None);
        assert_eq!(Action::from_discrete(Variant::Advanced, 30), None);
    }
}
