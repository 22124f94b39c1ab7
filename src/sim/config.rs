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
            max_steps: 50,
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

/// Largest accepted episode length: keeps step counters and per-episode series bounded.
pub const MAX_EPISODE_STEPS: u32 = 1_000_000;

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

    pub fn validate(&self) -> Result<(), ConfigError> {
        check_range("obs_noise", self.obs_noise, 0.0, 1.0, false, "0.0 ..= 1.0")?;
        check_range("action_penalty", self.action_penalty, 0.0, 10.0, false, "0.0 ..= 10.0")?;
        check_range("threshold", self.threshold, 0.0, 1.0, true, "0.0 ..< 1.0")?;
        if !(1..=MAX_EPISODE_STEPS).contains(&self.max_steps) {
            return Err(ConfigError {
                field: "max_steps",
                value: self.max_steps.to_string(),
                allowed: "1 ..= 1000000",
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
}
