//! The rule-based agent's table: for every input reading (and, advanced, ratio category) the
//! action with the highest *expected* immediate reward, computed in closed form from the model.
//!
//! The reference fills its table with one noisy sample per cell and treats the noisy reading as
//! the true amount. Here each cell is an expectation: over the accuracy noise (closed form, see
//! `accuracy::accuracy_law`) and over the batch totals that could have produced the reading,
//! weighted by the input generator's exact prior and the sensor's likelihood. With no sensor
//! noise that weighting is a point mass on the reading itself. Decisions are array lookups.
//!
//! `rba-hold` is the penalty-aware variant: a change of speed must pay back its expected penalty
//! (charged only when the accuracy clears the threshold) within the time the current input regime
//! is expected to last: one step for random input, the expected rest of a pattern for seasonal
//! input (see [`hold_horizon`]). It keeps its speed on ties.

use serde::Serialize;

use super::accuracy::{accuracy_law, noiseless_accuracy, ModeEffect};
use super::config::{ConfigError, InputKind, LineConfig, Setup, Variant};
use super::input::{prior, MAX_TOTAL};
use super::line::{Action, Observation};
use super::material::{Category, SortMode, CATEGORIES};
use super::observation::{level, likelihood, LEVELS};
use super::reward::expected_reward;
use super::speed::SPEED_COUNT;

/// Expected reward (no penalty) and probability of clearing the threshold of one action.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Value {
    reward: f64,
    p_above: f64,
}

impl Value {
    /// Value over `horizon` steps of moving to this action now, paying the penalty once.
    fn after_change(self, penalty: f64, horizon: f64) -> f64 {
        horizon * self.reward - self.p_above * penalty
    }
}

/// The precomputed decisions of `rba` and `rba-hold` for one line configuration.
#[derive(Clone, Debug)]
pub struct RbaTable {
    variant: Variant,
    /// Best action per cell (`cell = level * 3 + category`).
    best: Vec<Action>,
    /// Best action per cell and current speed (`cell * SPEED_COUNT + speed`).
    hold: Vec<Action>,
}

/// The actions an agent chooses among: speeds, times the modes of the advanced line.
/// (In the order of the Gymnasium actions: the table's ties go to the first, the slowest.)
fn options(variant: Variant) -> Vec<Action> {
    (0..Action::count(variant)).map(|a| Action::from_discrete(variant, a).expect("below the count")).collect()
}

/// The expected value of `action` on a batch of `total` units and `category` (noiseless table).
fn value_at(config: &LineConfig, total: usize, category: Category, action: Action) -> Value {
    let occupancy = total as f64 / 100.0;
    let e = ModeEffect::of(config.variant, action.mode, category);
    let c = noiseless_accuracy(occupancy, action.speed_index, e);
    let law = accuracy_law(c, e, config.threshold);
    Value { reward: expected_reward(&law, config.threshold, action.speed_index, 0.0), p_above: law.p_above }
}

impl RbaTable {
    pub fn build(config: &LineConfig) -> Self {
        let joint = prior(config.input);
        let options = options(config.variant);
        let mut best = Vec::with_capacity(LEVELS * CATEGORIES.len());
        let mut hold = Vec::with_capacity(LEVELS * CATEGORIES.len() * SPEED_COUNT);
        for reading in 0..LEVELS {
            for category in CATEGORIES {
                // Posterior weight of each true total given the reading (and category).
                let mut weights: Vec<(usize, Category, f64)> = Vec::new();
                for (total, by_category) in joint.iter().enumerate() {
                    let lik = likelihood(reading, total, config.obs_noise);
                    if lik == 0.0 {
                        continue;
                    }
                    match config.variant {
                        Variant::Advanced => weights.push((total, category, by_category[category.index()] * lik)),
                        Variant::Basic => {
                            for c in CATEGORIES {
                                weights.push((total, c, by_category[c.index()] * lik));
                            }
                        }
                    }
                }
                let mass: f64 = weights.iter().map(|w| w.2).sum();
                if mass <= 0.0 {
                    // A reading the generator cannot produce: trust it as the true amount.
                    weights = vec![(reading, category, 1.0)];
                }
                let mass: f64 = weights.iter().map(|w| w.2).sum();
                let values: Vec<Value> = options
                    .iter()
                    .map(|&action| {
                        weights.iter().fold(Value::default(), |acc, &(total, c, w)| {
                            let v = value_at(config, total, c, action);
                            Value {
                                reward: acc.reward + w / mass * v.reward,
                                p_above: acc.p_above + w / mass * v.p_above,
                            }
                        })
                    })
                    .collect();
                best.push(argmax(&options, &values, None, 0.0, 1.0));
                let horizon = hold_horizon(config.input);
                for current in 0..SPEED_COUNT {
                    hold.push(argmax(&options, &values, Some(current), config.action_penalty, horizon));
                }
            }
        }
        RbaTable { variant: config.variant, best, hold }
    }

    fn cell(&self, observation: Observation) -> usize {
        let category = match self.variant {
            Variant::Basic => Category::Basic, // the basic line has no ratio sensor
            Variant::Advanced => observation.category,
        };
        level(observation.quantity) * CATEGORIES.len() + category.index()
    }

    /// `rba`: the action with the highest expected immediate reward, ignoring the switching
    /// penalty (as the reference's agent does).
    pub fn decide(&self, observation: Observation) -> Action {
        self.best[self.cell(observation)]
    }

    /// `rba-hold`: the best action after the expected cost of changing from `current_speed`.
    pub fn decide_holding(&self, observation: Observation, current_speed: usize) -> Action {
        self.hold[self.cell(observation) * SPEED_COUNT + current_speed]
    }

    /// The whole table, for clients that decide without this library (`sorting_line policy`):
    /// `(rba, rba_hold)`, where `rba[level * 3 + category]` is what [`decide`](Self::decide)
    /// returns for a reading of that level (0..=100, see `observation::level`) and ratio category,
    /// and `rba_hold[(level * 3 + category) * SPEED_COUNT + current_speed]` what
    /// [`decide_holding`](Self::decide_holding) returns. The basic line decides from category slot
    /// 0 (it has no ratio sensor); its three slots are equal.
    pub fn cells(&self) -> (&[Action], &[Action]) {
        (&self.best, &self.hold)
    }
}

/// The tables of `rba` and `rba-hold` for one of the paper's setups as one JSON object, what
/// `sorting_line policy` prints and the extension's `policy` returns: `setup`, `variant`, `levels`,
/// `rba` (`[speed_index, mode]` per cell `level * 3 + category`), `rba_hold` (per cell, one pair
/// per current speed 0..=9) and the line's `config`.
pub fn policy(setup: Setup, variant: Variant) -> serde_json::Value {
    let config = LineConfig::for_setup(setup, variant);
    let table = RbaTable::build(&config);
    let (best, hold) = table.cells();
    let pair = |a: &Action| [a.speed_index, a.mode.index()];
    serde_json::json!({
        "setup": setup,
        "variant": variant,
        "levels": LEVELS,
        "rba": best.iter().map(pair).collect::<Vec<_>>(),
        "rba_hold": hold.chunks(SPEED_COUNT).map(|c| c.iter().map(pair).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "config": config,
    })
}

/// How many steps a reading's regime is expected to last, counting the current one: the horizon
/// over which `rba-hold` lets a change of speed pay back its penalty. Random input is fresh every
/// step (1). A seasonal pattern lasts L = 10, 11 or 12 steps (uniform); seen at a random step, its
/// expected rest including that step is E\[L^2\] / (2 E\[L\]) + 1/2 (length-biased sampling).
pub fn hold_horizon(input: InputKind) -> f64 {
    match input {
        InputKind::Random => 1.0,
        InputKind::Seasonal | InputKind::Seasonal3 => {
            let lengths = [10.0, 11.0, 12.0];
            let mean: f64 = lengths.iter().sum::<f64>() / 3.0;
            let mean_sq: f64 = lengths.iter().map(|l| l * l).sum::<f64>() / 3.0;
            mean_sq / (2.0 * mean) + 0.5
        }
    }
}

/// The option with the highest value; ties go to the earliest (slowest) option, except that
/// with a current speed an option keeping that speed wins ties (and pays no penalty).
fn argmax(options: &[Action], values: &[Value], current: Option<usize>, penalty: f64, horizon: f64) -> Action {
    let score = |i: usize| match current {
        Some(cur) if options[i].speed_index != cur => values[i].after_change(penalty, horizon),
        _ => horizon * values[i].reward,
    };
    let mut best = 0;
    for i in 1..options.len() {
        let keeps = current == Some(options[i].speed_index) && current != Some(options[best].speed_index);
        if score(i) > score(best) || (keeps && score(i) >= score(best)) {
            best = i;
        }
    }
    options[best]
}

/// One row of the expected-reward analysis printed by `sorting_line table`.
#[derive(Clone, Debug, Serialize)]
pub struct AnalysisRow {
    pub variant: Variant,
    /// True occupancy of the batch, 0..=1.
    pub occupancy: f64,
    pub category: Category,
    pub speed: f64,
    pub mode: SortMode,
    /// Accuracy before the noise is subtracted.
    pub noiseless_accuracy: f64,
    pub expected_accuracy: f64,
    pub p_above_threshold: f64,
    /// Expected immediate reward without switching penalty.
    pub expected_reward: f64,
    /// Whether this is the best action for this occupancy (and category).
    pub best: bool,
}

/// The columns of `sorting_line table`'s CSV, in the order of [`AnalysisRow::fields`].
pub const ANALYSIS_COLUMNS: [&str; 10] = [
    "variant",
    "occupancy",
    "category",
    "speed",
    "mode",
    "noiseless_accuracy",
    "expected_accuracy",
    "p_above_threshold",
    "expected_reward",
    "best",
];

impl AnalysisRow {
    /// The row as `sorting_line table` prints it, one text per [`ANALYSIS_COLUMNS`] entry:
    /// occupancy to 2 decimals, speed to 1, the accuracies, probability and reward to 6, the
    /// category, mode and `best` as numbers (the one formatting of the CLI and the extension).
    pub fn fields(&self) -> [String; ANALYSIS_COLUMNS.len()] {
        [
            self.variant.to_string(),
            format!("{:.2}", self.occupancy),
            (self.category as u8).to_string(),
            format!("{:.1}", self.speed),
            (self.mode as u8).to_string(),
            format!("{:.6}", self.noiseless_accuracy),
            format!("{:.6}", self.expected_accuracy),
            format!("{:.6}", self.p_above_threshold),
            format!("{:.6}", self.expected_reward),
            u8::from(self.best).to_string(),
        ]
    }
}

/// The analysis `sorting_line table --variant VARIANT --threshold THRESHOLD` prints: [`analysis`]
/// of the default line with that variant and threshold, the threshold checked as
/// [`LineConfig::validate`] checks it.
pub fn analysis_table(variant: Variant, threshold: f64) -> Result<Vec<AnalysisRow>, ConfigError> {
    let config = LineConfig { variant, threshold, ..LineConfig::default() };
    config.validate()?;
    Ok(analysis(&config))
}

/// The noise-free model analysis behind the agent: every (occupancy, category, speed, mode).
/// The basic line has one category (its rows say `basic`).
pub fn analysis(config: &LineConfig) -> Vec<AnalysisRow> {
    let options = options(config.variant);
    let categories: &[Category] = match config.variant {
        Variant::Basic => &[Category::Basic],
        Variant::Advanced => &CATEGORIES,
    };
    let mut rows = Vec::new();
    for total in 0..=MAX_TOTAL {
        for &category in categories {
            let values: Vec<Value> = options.iter().map(|&a| value_at(config, total, category, a)).collect();
            let chosen = argmax(&options, &values, None, 0.0, 1.0);
            for (&action, value) in options.iter().zip(&values) {
                let e = ModeEffect::of(config.variant, action.mode, category);
                let c = noiseless_accuracy(total as f64 / 100.0, action.speed_index, e);
                rows.push(AnalysisRow {
                    variant: config.variant,
                    occupancy: total as f64 / 100.0,
                    category,
                    speed: action.speed(),
                    mode: action.mode,
                    noiseless_accuracy: c,
                    expected_accuracy: accuracy_law(c, e, config.threshold).mean,
                    p_above_threshold: value.p_above,
                    expected_reward: value.reward,
                    best: action == chosen,
                });
            }
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::config::Setup;

    fn obs(q: f64, c: Category) -> Observation {
        Observation { quantity: q, category: c }
    }

    #[test]
    fn noise_free_basic_picks_fastest_speed_within_limit() {
        let table = RbaTable::build(&LineConfig::for_setup(Setup::A, Variant::Basic));
        // Occupancy 0.5: limit of speed 0.6 is 0.5 -> speed index 5.
        assert_eq!(table.decide(obs(0.5, Category::Basic)).speed_index, 5);
        // Occupancy 0.15: the reference's noisy table says 0.8; the expectation says 0.9
        // (limit 0.2 covers 0.15 with no excess).
        assert_eq!(table.decide(obs(0.15, Category::Basic)).speed_index, 8);
        assert_eq!(table.decide(obs(0.05, Category::Basic)).speed_index, 9);
        assert_eq!(table.decide(obs(0.95, Category::Basic)).speed_index, 0);
    }

    #[test]
    fn advanced_matches_mode_to_category() {
        let table = RbaTable::build(&LineConfig::for_setup(Setup::A, Variant::Advanced));
        for c in CATEGORIES {
            for q in [0.1, 0.4, 0.77] {
                assert_eq!(table.decide(obs(q, c)).mode, SortMode::for_category(c));
            }
        }
        // With the mode matched, up to 0.05 of excess costs nothing: one notch faster than basic.
        assert_eq!(table.decide(obs(0.54, Category::Basic)).speed_index, 5);
    }

    #[test]
    fn hold_keeps_speed_when_change_does_not_pay() {
        let config = LineConfig::for_setup(Setup::B, Variant::Basic);
        let table = RbaTable::build(&config);
        let o = obs(0.5, Category::Basic);
        assert_eq!(table.decide(o).speed_index, 5);
        // One notch slower costs 0.056 of speed reward a step: over a ~6-step pattern that is
        // less than the 0.5 penalty.
        assert_eq!(table.decide_holding(o, 4).speed_index, 4);
        // Three notches slower costs 0.17 a step: a change pays back within the pattern.
        assert_eq!(table.decide_holding(o, 2).speed_index, 5);
        // Too fast for 0.5 (accuracy collapses): changing pays even with the penalty.
        assert_ne!(table.decide_holding(o, 9).speed_index, 9);
        assert_eq!(table.decide_holding(o, 5).speed_index, 5);
    }

    #[test]
    fn hold_horizon_is_one_for_random_input_and_the_rest_of_a_pattern_otherwise() {
        assert_eq!(hold_horizon(InputKind::Random), 1.0);
        let h = hold_horizon(InputKind::Seasonal);
        assert!((h - (365.0 / 3.0 / 22.0 + 0.5)).abs() < 1e-12, "{h}");
    }

    #[test]
    fn exported_cells_agree_with_decide_for_every_cell() {
        for setup in crate::sim::config::SETUPS {
            for variant in crate::sim::config::VARIANTS {
                let table = RbaTable::build(&LineConfig::for_setup(setup, variant));
                let (best, hold) = table.cells();
                assert_eq!(best.len(), LEVELS * 3);
                assert_eq!(hold.len(), LEVELS * 3 * SPEED_COUNT);
                for l in 0..LEVELS {
                    for c in CATEGORIES {
                        let o = obs(l as f64 / 100.0, c);
                        // The basic line ignores the category: any slot gives slot 0's decision.
                        let cell = l * 3 + if variant == Variant::Basic { 0 } else { c.index() };
                        if variant == Variant::Basic {
                            assert_eq!(best[l * 3 + c.index()], best[cell], "{setup:?} basic level {l}: slots differ");
                        }
                        assert_eq!(table.decide(o), best[cell], "{setup:?} {variant} level {l} {c:?}");
                        for speed in 0..SPEED_COUNT {
                            assert_eq!(
                                table.decide_holding(o, speed),
                                hold[cell * SPEED_COUNT + speed],
                                "{setup:?} {variant} level {l} {c:?} speed {speed}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn analysis_has_one_best_row_per_cell() {
        let rows = analysis(&LineConfig::for_setup(Setup::A, Variant::Advanced));
        assert_eq!(rows.len(), 101 * 3 * 30);
        assert_eq!(rows.iter().filter(|r| r.best).count(), 101 * 3);
    }

    #[test]
    fn the_table_is_the_default_lines_analysis_as_the_cli_prints_it() {
        let rows = analysis_table(Variant::Advanced, 0.5).unwrap();
        let config = LineConfig { variant: Variant::Advanced, threshold: 0.5, ..LineConfig::default() };
        assert_eq!(rows.len(), analysis(&config).len());
        // Occupancy 0.3, category B-rich, speed 0.4, mode positive: the fields in the columns' order.
        let row = rows
            .iter()
            .find(|r| {
                r.occupancy == 0.3 && r.category == Category::Negative && r.speed == 0.4 && r.mode == SortMode::Positive
            })
            .unwrap();
        let fields = row.fields();
        assert_eq!(fields[..5], ["advanced", "0.30", "2", "0.4", "1"]);
        assert_eq!(fields[5], format!("{:.6}", row.noiseless_accuracy));
        assert_eq!(fields[8], format!("{:.6}", row.expected_reward));
        assert_eq!(ANALYSIS_COLUMNS[5], "noiseless_accuracy");
        let error = analysis_table(Variant::Basic, 1.0).unwrap_err();
        assert_eq!(error.to_string(), "threshold = 1 is out of range: allowed 0.0 ..< 1.0");
    }
}
