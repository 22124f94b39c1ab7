//! The non-learning agents used by `sorting_line eval`, the benchmark and the tests:
//! `rba`, `rba-hold`, `bayes` (the Bayes-optimal policy, basic line with exact readings), a
//! seeded `random`, and `constant:K[:M|:cat]`.

use std::fmt;
use std::str::FromStr;

use super::bayes::BayesAgent;
use super::config::{LineConfig, Variant};
use super::line::{Action, Observation};
use super::material::{SortMode, SORT_MODES};
use super::rba::RbaTable;
use super::rng::{integer, stream, SimRng, Stream};
use super::speed::SPEED_COUNT;

/// Which sort mode a constant-speed agent uses (advanced line).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeChoice {
    Fixed(SortMode),
    /// The mode matching the observed ratio category.
    Observed,
}

/// An agent as named on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AgentSpec {
    Rba,
    RbaHold,
    Bayes,
    Random,
    Constant { speed_index: usize, mode: ModeChoice },
}

impl FromStr for AgentSpec {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (last_speed, last_mode) = (SPEED_COUNT - 1, SORT_MODES.len() - 1);
        let usage = format!(
            "allowed: rba, rba-hold, bayes, random, constant:K, constant:K:cat, constant:K:M (K = 0..{last_speed}, M = 0..{last_mode})"
        );
        match s {
            "rba" => return Ok(AgentSpec::Rba),
            "rba-hold" => return Ok(AgentSpec::RbaHold),
            "bayes" => return Ok(AgentSpec::Bayes),
            "random" => return Ok(AgentSpec::Random),
            _ => {}
        }
        let parts: Vec<&str> = s.split(':').collect();
        if parts[0] != "constant" || !(2..=3).contains(&parts.len()) {
            return Err(format!("unknown agent '{s}': {usage}"));
        }
        let speed_index =
            parts[1].parse::<usize>().ok().filter(|&k| k < SPEED_COUNT).ok_or_else(|| {
                format!("speed index '{}' in '{s}' is out of range: allowed 0..{last_speed}", parts[1])
            })?;
        let mode = match parts.get(2) {
            None => ModeChoice::Fixed(SortMode::Basic),
            Some(&"cat") => ModeChoice::Observed,
            Some(m) => ModeChoice::Fixed(
                m.parse::<u8>()
                    .ok()
                    .and_then(SortMode::from_index)
                    .ok_or_else(|| format!("mode '{m}' in '{s}' is out of range: allowed 0..{last_mode} or cat"))?,
            ),
        };
        Ok(AgentSpec::Constant { speed_index, mode })
    }
}

impl fmt::Display for AgentSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AgentSpec::Rba => f.write_str("rba"),
            AgentSpec::RbaHold => f.write_str("rba-hold"),
            AgentSpec::Bayes => f.write_str("bayes"),
            AgentSpec::Random => f.write_str("random"),
            AgentSpec::Constant { speed_index, mode: ModeChoice::Observed } => write!(f, "constant:{speed_index}:cat"),
            AgentSpec::Constant { speed_index, mode: ModeChoice::Fixed(SortMode::Basic) } => {
                write!(f, "constant:{speed_index}")
            }
            AgentSpec::Constant { speed_index, mode: ModeChoice::Fixed(m) } => {
                write!(f, "constant:{speed_index}:{}", m.index())
            }
        }
    }
}

/// A ready-to-act agent. The random agent's generator is boxed: its state would otherwise be most
/// of every agent's size (clippy's large_enum_variant), and a draw costs far more than the
/// indirection.
#[derive(Clone, Debug)]
pub enum Agent {
    Rba(RbaTable),
    RbaHold(RbaTable),
    Bayes(BayesAgent),
    Random { rng: Box<SimRng>, variant: Variant },
    Constant { speed_index: usize, mode: ModeChoice },
}

impl Agent {
    /// Builds the agent for a line configuration. Mode choices need the advanced line.
    pub fn new(spec: AgentSpec, config: &LineConfig, seed: u64) -> Result<Self, String> {
        Ok(match spec {
            AgentSpec::Rba => Agent::Rba(RbaTable::build(config)),
            AgentSpec::RbaHold => Agent::RbaHold(RbaTable::build(config)),
            AgentSpec::Bayes => Agent::Bayes(BayesAgent::new(config)?),
            AgentSpec::Random => Agent::Random { rng: Box::new(stream(seed, Stream::Agent)), variant: config.variant },
            AgentSpec::Constant { mode, .. }
                if config.variant == Variant::Basic && mode != ModeChoice::Fixed(SortMode::Basic) =>
            {
                return Err(format!("agent '{spec}' sets a sort mode, which only the advanced line has"));
            }
            AgentSpec::Constant { speed_index, mode } => Agent::Constant { speed_index, mode },
        })
    }

    /// Starts an episode: restarts the random agent's stream (each evaluation episode reseeds its
    /// agent) and the Bayes agent's step count and belief.
    pub fn reseed(&mut self, seed: u64) {
        match self {
            Agent::Random { rng, .. } => **rng = stream(seed, Stream::Agent),
            Agent::Bayes(agent) => agent.restart(),
            _ => {}
        }
    }

    /// The action for an observation, given the belt's current speed index.
    pub fn act(&mut self, observation: Observation, current_speed: usize) -> Action {
        match self {
            Agent::Rba(table) => table.decide(observation),
            Agent::RbaHold(table) => table.decide_holding(observation, current_speed),
            Agent::Bayes(agent) => agent.act(observation, current_speed),
            Agent::Random { rng, variant } => {
                let n = Action::count(*variant);
                Action::from_discrete(*variant, integer(rng, 0, n as u32) as usize).expect("in range")
            }
            Agent::Constant { speed_index, mode } => Action::new(
                *speed_index,
                match mode {
                    ModeChoice::Fixed(m) => *m,
                    ModeChoice::Observed => SortMode::for_category(observation.category),
                },
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_print() {
        for s in ["rba", "rba-hold", "bayes", "random", "constant:3", "constant:9:cat", "constant:0:2"] {
            assert_eq!(s.parse::<AgentSpec>().unwrap().to_string(), s);
        }
        assert!("constant:10".parse::<AgentSpec>().unwrap_err().contains("allowed 0..9"));
        assert!("constant:1:5".parse::<AgentSpec>().unwrap_err().contains("allowed 0..2 or cat"));
        assert!("fancy".parse::<AgentSpec>().unwrap_err().ends_with("constant:K:M (K = 0..9, M = 0..2)"));
        assert!("ppo".parse::<AgentSpec>().unwrap_err().starts_with("unknown agent 'ppo'"));
    }

    #[test]
    fn modes_need_the_advanced_line() {
        let basic = LineConfig::default();
        assert!(Agent::new("constant:3:cat".parse().unwrap(), &basic, 0).is_err());
        assert!(Agent::new("constant:3".parse().unwrap(), &basic, 0).is_ok());
    }
}
