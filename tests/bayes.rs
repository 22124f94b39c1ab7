//! The Bayes-optimal policy (`sim::bayes`) held against what it claims to be:
//! - on random input without sensor noise or penalty (A basic) it is `rba`, decision for decision;
//! - under its own exact model no other reading-and-speed policy expects more (rba, rba-hold,
//!   every constant speed, evaluated exactly by the same backward induction);
//! - the model is the line's: over 1,000 episodes the mean rewards of `bayes` and `rba-hold`
//!   on the real line match the model's expectations within 4 standard errors;
//! - the clairvoyant oracle is above it on every seed.

use sorting_line::eval::{add_oracle, evaluate};
use sorting_line::sim::agent::{Agent, AgentSpec};
use sorting_line::sim::bayes::{expected_reward_of, BayesPolicy};
use sorting_line::sim::evolution::Schedule;
use sorting_line::sim::{LineConfig, Setup, Variant};

/// The model's expected episode reward of an agent that decides from (reading, speed) alone.
fn expected_of(config: &LineConfig, spec: &str) -> f64 {
    if spec == "bayes" {
        return BayesPolicy::build(config).unwrap().expected_reward();
    }
    let mut agent = Agent::new(spec.parse().unwrap(), config, 0).unwrap();
    expected_reward_of(config, |observation, speed| agent.act(observation, speed)).unwrap()
}

#[test]
fn on_a_basic_bayes_is_rba() {
    let config = LineConfig::for_setup(Setup::A, Variant::Basic);
    let bayes = evaluate(&config, &Schedule::default(), AgentSpec::Bayes, 10, 42, |_| {}).unwrap();
    let rba = evaluate(&config, &Schedule::default(), AgentSpec::Rba, 10, 42, |_| {}).unwrap();
    let rewards = |s: &sorting_line::eval::EvalSummary| s.per_episode.iter().map(|e| e.reward).collect::<Vec<_>>();
    assert_eq!(rewards(&bayes), rewards(&rba));
    let planned = BayesPolicy::build(&config).unwrap().expected_reward();
    assert!((planned - expected_of(&config, "rba")).abs() < 1e-9, "{planned}");
}

#[test]
fn no_reading_and_speed_policy_expects_more_than_bayes() {
    for setup in [Setup::A, Setup::B] {
        let config = LineConfig::for_setup(setup, Variant::Basic);
        let best = BayesPolicy::build(&config).unwrap().expected_reward();
        let mut others: Vec<String> = ["rba", "rba-hold"].map(String::from).to_vec();
        others.extend((0..10).map(|k| format!("constant:{k}")));
        for other in &others {
            let value = expected_of(&config, other);
            assert!(value <= best + 1e-9, "{setup:?}: {other} expects {value} > bayes {best}");
        }
        if setup == Setup::B {
            // Knowing how long a pattern has run is worth something over rba-hold's fixed horizon.
            assert!(best > expected_of(&config, "rba-hold") + 0.5, "{best}");
        }
    }
}

#[test]
fn the_model_is_the_lines_over_a_thousand_episodes() {
    let config = LineConfig::for_setup(Setup::B, Variant::Basic);
    for spec in ["bayes", "rba-hold"] {
        let run = evaluate(&config, &Schedule::default(), spec.parse().unwrap(), 1000, 1000, |_| {}).unwrap();
        let expected = expected_of(&config, spec);
        assert!(
            (run.reward_mean - expected).abs() < 4.0 * run.reward_se,
            "{spec}: line {} +- {} against the model's {expected}",
            run.reward_mean,
            run.reward_se
        );
    }
}

#[test]
fn the_oracle_is_above_bayes_on_every_seed() {
    for setup in [Setup::A, Setup::B] {
        let config = LineConfig::for_setup(setup, Variant::Basic);
        let mut summary = evaluate(&config, &Schedule::default(), AgentSpec::Bayes, 10, 42, |_| {}).unwrap();
        add_oracle(&mut summary).unwrap();
        assert!(summary.per_episode.iter().all(|e| e.gap.unwrap() >= 0.0), "{setup:?}");
    }
}
