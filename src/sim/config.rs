//! The line's configuration: one validated struct, filled from CLI flags, a YAML/JSON file or
//! ROS parameters alike. A value outside its range is an error naming the field, the value and
//! the range, so a bad parameter file fails at start instead of producing a strange benchmark.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// Basic line (speed only) or advanced line (speed, sort mode and the ratio sensor).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    #[default]
    Basic,
    Advanced,
}

/// Which input generator feeds the line (see `input.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InputKind {
    /// Uniform random batches (the reference's "r").
    #[default]
    Random,
    /// Nine seasonal patterns of amount x ratio (the reference's "s9", used by the paper).
    Seasonal,
    /// Three seasonal amount patterns (the reference's "s3").
    Seasonal3,
}

/// The paper's four benchmark setups.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Setup {
    A,
    B,
    C,
    D,
}

pub const SETUPS: [Setup; 4] = [Setup::A, Setup::B, Setup::C, Setup::D];
pub const VARIANTS: [Variant; 2] = [Variant::Basic, Variant::Advanced];
pub const INPUT_KINDS: [InputKind; 3] = [InputKind::Random, InputKind::Seasonal, InputKind::Seasonal3];

/// Everything that defines the dynamics of one line. Seeds, timing and transport are not here:
/// they belong to whoever runs the line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LineConfig {
    pub variant: Variant,
    pub input: InputKind,
    /// Relative noise of the input sensor: reading = amount * (1 + U(-n, n)).
    pub obs_noise: f64,
    /// Reward subtracted when the belt speed changes (sort-mode changes are free).
    pub action_penalty: f64,
    /// Accuracy below which a step earns a flat -0.1.
    pub threshold: f64,
    /// Episode length in steps; the step that reaches it is `truncated`.
    pub max_steps: u32,
}

impl Default for LineConfig {
    fn default() -> Self {
        LineConfig {
            variant: Variant::Basic,
            input: InputKind::Random,
            obs_noise: 0.0,
            action_penalty: 0.0,
            threshold: 0.7,
            max_steps: EPISODE_STEPS,
        }
    }
}

/// A configuration value outside its allowed range.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigError {
    pub field: &'static str,
    pub value: String,
    pub allowed: &'static str,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} = {} is out of range: allowed {}", self.field, self.value, self.allowed)
    }
}

impl std::error::Error for ConfigError {}

/// Checks that `value` is finite and in `lo..=hi` (or `lo..hi` with `hi_open`).
fn check_range(
    field: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    hi_open: bool,
    allowed: &'static str,
) -> Result<(), ConfigError> {
    let ok = value.is_finite() && value >= lo && if hi_open { value < hi } else { value <= hi };
    if ok {
        Ok(())
    } else {
        Err(ConfigError { field, value: value.to_string(), allowed })
    }
}

/// The paper's episode length, in steps: `LineConfig`'s default `max_steps`, and so the length of
/// `sorting_line eval`, `oracle` and `trace` unless `--max-steps` says otherwise.
pub const EPISODE_STEPS: u32 = 50;

/// The paper's evaluation: `EVAL_EPISODES` episodes of the default length, episode i reset with
/// seed `EVAL_FIRST_SEED + i` (seeds 42..51): `sorting_line eval`'s and `oracle`'s defaults, and
/// the Python package's (`vocabulary.EVAL_FIRST_SEED`, `sorting-line-eval`).
pub const EVAL_FIRST_SEED: u64 = 42;
pub const EVAL_EPISODES: usize = 10;

/// Largest accepted episode length: keeps step counters and per-episode series bounded.
pub const MAX_EPISODE_STEPS: u32 = 1_000_000;

/// Most lines one node process hosts (`sorting_line node --lines`: memory and message rate stay
/// bounded). Here, below the node, so that the Python package's batched trainer and line bank
/// take it from the library (`vocabulary.NODE_LINES`) instead of writing 64 again.
pub const MAX_NODE_LINES: u32 = 64;

/// The bounds `validate` accepts (`threshold`'s upper bound is open), named once so that the
/// node's parameter descriptors state exactly what is enforced.
pub const OBS_NOISE_RANGE: (f64, f64) = (0.0, 1.0);
pub const ACTION_PENALTY_RANGE: (f64, f64) = (0.0, 10.0);
pub const THRESHOLD_RANGE: (f64, f64) = (0.0, 1.0);

/// The ranges above as every error message and parameter description writes them (`..=` closed,
/// `..<` open at the top); a test checks that each text says what its numbers say.
pub const OBS_NOISE_ALLOWED: &str = "0.0 ..= 1.0";
pub const ACTION_PENALTY_ALLOWED: &str = "0.0 ..= 10.0";
pub const THRESHOLD_ALLOWED: &str = "0.0 ..< 1.0";
pub const MAX_STEPS_ALLOWED: &str = "1 ..= 1000000";
pub const NODE_LINES_ALLOWED: &str = "1 ..= 64";

impl LineConfig {
    /// The configuration of one of the paper's setups (threshold 0.7, 50-step episodes).
    pub fn for_setup(setup: Setup, variant: Variant) -> Self {
        let (input, obs_noise, action_penalty) = match setup {
            Setup::A => (InputKind::Random, 0.0, 0.0),
            Setup::B => (InputKind::Seasonal, 0.0, 0.5),
            Setup::C => (InputKind::Random, 0.3, 0.0),
            Setup::D => (InputKind::Seasonal, 0.3, 0.5),
        };
        LineConfig { variant, input, obs_noise, action_penalty, ..LineConfig::default() }
    }

    /// The allowed range of `obs_noise`: the one check for every source of the value (flags,
    /// parameter files, ROS parameters, evolution schedules).
    pub fn check_obs_noise(value: f64) -> Result<(), ConfigError> {
        check_range("obs_noise", value, OBS_NOISE_RANGE.0, OBS_NOISE_RANGE.1, false, OBS_NOISE_ALLOWED)
    }

    /// The allowed range of `action_penalty` (see [`LineConfig::check_obs_noise`]).
    pub fn check_action_penalty(value: f64) -> Result<(), ConfigError> {
        check_range(
            "action_penalty",
            value,
            ACTION_PENALTY_RANGE.0,
            ACTION_PENALTY_RANGE.1,
            false,
            ACTION_PENALTY_ALLOWED,
        )
    }

    /// The allowed range of `threshold` (see [`LineConfig::check_obs_noise`]).
    pub fn check_threshold(value: f64) -> Result<(), ConfigError> {
        check_range("threshold", value, THRESHOLD_RANGE.0, THRESHOLD_RANGE.1, true, THRESHOLD_ALLOWED)
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        Self::check_obs_noise(self.obs_noise)?;
        Self::check_action_penalty(self.action_penalty)?;
        Self::check_threshold(self.threshold)?;
        if !(1..=MAX_EPISODE_STEPS).contains(&self.max_steps) {
            return Err(ConfigError {
                field: "max_steps",
                value: self.max_steps.to_string(),
                allowed: MAX_STEPS_ALLOWED,
            });
        }
        Ok(())
    }

    /// Parses YAML (JSON is YAML too) into a validated configuration.
    pub fn from_yaml(text: &str) -> Result<Self, String> {
        let config: LineConfig = serde_yaml::from_str(text).map_err(|e| e.to_string())?;
        config.validate().map_err(|e| e.to_string())?;
        Ok(config)
    }
}

/// Parses the lowercase names used on the command line and in parameter files.
macro_rules! from_str_by_name {
    ($ty:ty, $($name:literal => $value:expr),+ $(,)?) => {
        impl FromStr for $ty {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, String> {
                match s {
                    $($name => Ok($value),)+
                    _ => Err(format!(
                        "'{}' is not a valid {}: allowed {}",
                        s, stringify!($ty), [$($name),+].join(", ")
                    )),
                }
            }
        }
        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                let name = match self { $(v if *v == $value => $name,)+ _ => unreachable!() };
                f.write_str(name)
            }
        }
    };
}

from_str_by_name!(Variant, "basic" => Variant::Basic, "advanced" => Variant::Advanced);
from_str_by_name!(InputKind, "random" => InputKind::Random, "seasonal" => InputKind::Seasonal,
    "seasonal3" => InputKind::Seasonal3);
from_str_by_name!(Setup, "A" => Setup::A, "B" => Setup::B, "C" => Setup::C, "D" => Setup::D);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn setups_are_the_papers() {
        let d = LineConfig::for_setup(Setup::D, Variant::Advanced);
        assert_eq!((d.input, d.obs_noise, d.action_penalty, d.threshold), (InputKind::Seasonal, 0.3, 0.5, 0.7));
        for s in SETUPS {
            LineConfig::for_setup(s, Variant::Basic).validate().unwrap();
        }
    }

    #[test]
    fn out_of_range_values_name_field_value_and_range() {
        let bad = LineConfig { threshold: 1.0, ..LineConfig::default() };
        let err = bad.validate().unwrap_err().to_string();
        assert_eq!(err, "threshold = 1 is out of range: allowed 0.0 ..< 1.0");
        let nan = LineConfig { obs_noise: f64::NAN, ..LineConfig::default() };
        assert!(nan.validate().unwrap_err().to_string().starts_with("obs_noise = NaN"));
        let zero = LineConfig { max_steps: 0, ..LineConfig::default() };
        assert_eq!(zero.validate().unwrap_err().field, "max_steps");
    }

    #[test]
    fn yaml_fills_and_validates() {
        let c = LineConfig::from_yaml("variant: advanced\ninput: seasonal\naction_penalty: 0.5\n").unwrap();
        assert_eq!(c.variant, Variant::Advanced);
        assert_eq!(c.max_steps, 50);
        let e = LineConfig::from_yaml("obs_noise: 2.5\n").unwrap_err();
        assert!(e.contains("obs_noise = 2.5"), "{e}");
        let e = LineConfig::from_yaml("speed: 3\n").unwrap_err();
        assert!(e.contains("unknown field `speed`"), "{e}");
    }

    #[test]
    fn names_round_trip() {
        for v in VARIANTS {
            assert_eq!(v.to_string().parse::<Variant>().unwrap(), v);
        }
        assert!("fast".parse::<Variant>().unwrap_err().contains("allowed basic, advanced"));
    }

    #[test]
    fn allowed_texts_say_what_the_ranges_are() {
        let closed = |(lo, hi): (f64, f64)| format!("{lo:.1} ..= {hi:.1}");
        assert_eq!(OBS_NOISE_ALLOWED, closed(OBS_NOISE_RANGE));
        assert_eq!(ACTION_PENALTY_ALLOWED, closed(ACTION_PENALTY_RANGE));
        assert_eq!(THRESHOLD_ALLOWED, format!("{:.1} ..< {:.1}", THRESHOLD_RANGE.0, THRESHOLD_RANGE.1));
        assert_eq!(MAX_STEPS_ALLOWED, format!("1 ..= {MAX_EPISODE_STEPS}"));
        assert_eq!(NODE_LINES_ALLOWED, format!("1 ..= {MAX_NODE_LINES}"));
    }
}
