//! The clairvoyant oracle (`sim::oracle`) held against what it claims to be:
//! - the optimum: brute force over every action sequence of short episodes finds the same value,
//!   bit for bit, on every setup and variant; on full episodes no single changed action beats it;
//! - a ceiling: no built-in agent scores more on any seed 42..51 of any setup and variant;
//! - the library's own number: its actions replayed through `Line::step`, and through
//!   `sorting_line trace` from its `--json` output, give exactly its reward; `eval --gap` reports it.

use std::process::Command;

use serde_json::Value;
use sorting_line::eval::{add_oracle, evaluate};
use sorting_line::sim::agent::AgentSpec;
use sorting_line::sim::config::{SETUPS, VARIANTS};
use sorting_line::sim::evolution::Schedule;
use sorting_line::sim::oracle::{replay, solve};
use sorting_line::sim::{Action, Line, LineConfig, Setup, Variant};

/// Every action of a line: 10 speeds, times the 3 modes of the advanced line.
fn all_actions(variant: Variant) -> Vec<Action> {
    (0..if variant == Variant::Basic { 10 } else { 30 }).map(|a| Action::from_discrete(variant, a).unwrap()).collect()
}

/// The best episode reward over every action sequence from this point on.
fn brute_force(line: &Line, actions: &[Action]) -> f64 {
    if line.truncated() {
        return line.cumulative_reward();
    }
    actions
        .iter()
        .map(|&action| {
            let mut next = line.clone();
            next.step(action);
            brute_force(&next, actions)
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

#[test]
fn brute_force_over_every_action_sequence_agrees_on_short_episodes() {
    // Basic: 10^5 sequences of 5 steps; advanced: 30^3 of 3 steps and, for one seed, 30^4 of 4.
    for setup in SETUPS {
        for (variant, steps, seeds) in [
            (Variant::Basic, 5, &[42u64, 7, 1234][..]),
            (Variant::Advanced, 3, &[42, 7, 1234]),
            (Variant::Advanced, 4, &[43]),
        ] {
            let config = LineConfig { max_steps: steps, ..LineConfig::for_setup(setup, variant) };
            for &seed in seeds {
                let exhaustive = brute_force(&Line::new(config.clone(), seed), &all_actions(variant));
                let best = solve(&config, seed).unwrap();
                assert_eq!(best.reward, exhaustive, "{setup:?} {variant} {steps} steps seed {seed}");
                assert_eq!(replay(&config, seed, &best.actions), exhaustive);
            }
        }
    }
}

#[test]
fn no_single_changed_action_beats_the_optimum_of_a_full_episode() {
    for setup in SETUPS {
        for variant in VARIANTS {
            let config = LineConfig::for_setup(setup, variant);
            let best = solve(&config, 42).unwrap();
            for t in 0..best.actions.len() {
                for alternative in all_actions(variant) {
                    let mut actions = best.actions.clone();
                    actions[t] = alternative;
                    let reward = replay(&config, 42, &actions);
                    assert!(
                        reward <= best.reward,
                        "{setup:?} {variant}: step {t} -> {alternative:?} gives {reward} > {}",
                        best.reward
                    );
                }
            }
        }
    }
}

/// Every built-in agent that runs on the variant.
fn builtin_agents(variant: Variant) -> Vec<AgentSpec> {
    let mut names: Vec<String> = ["rba", "rba-hold", "random"].map(String::from).to_vec();
    for k in 0..10 {
        names.push(format!("constant:{k}"));
        if variant == Variant::Advanced {
            names.extend([format!("constant:{k}:cat"), format!("constant:{k}:1"), format!("constant:{k}:2")]);
        }
    }
    names.iter().map(|n| n.parse().unwrap()).collect()
}

#[test]
fn oracle_is_at_least_every_builtin_agent_on_every_seed() {
    for setup in SETUPS {
        for variant in VARIANTS {
            let config = LineConfig::for_setup(setup, variant);
            for spec in builtin_agents(variant) {
                let mut summary = evaluate(&config, &Schedule::default(), spec, 10, 42, |_| {}).unwrap();
                add_oracle(&mut summary).unwrap();
                for e in &summary.per_episode {
                    let (oracle, gap) = (e.oracle.unwrap(), e.gap.unwrap());
                    assert!(
                        oracle >= e.reward,
                        "{setup:?} {variant} {spec} seed {}: {} > oracle {oracle}",
                        e.seed,
                        e.reward
                    );
                    assert_eq!(gap, oracle - e.reward);
                }
                if !matches!(spec, AgentSpec::Rba | AgentSpec::RbaHold) {
                    continue;
                }
                if (setup, variant) == (Setup::A, Variant::Basic) {
                    // The oracle is tight: on A basic the accuracy noise is subtracted alike at every
                    // speed and the best speed clears the threshold whatever the draw, so knowing the
                    // draws is worth nothing and the expected-reward agent is exactly optimal.
                    assert!(
                        summary.per_episode.iter().all(|e| e.gap == Some(0.0)),
                        "{spec}: {:?}",
                        summary.per_episode
                    );
                } else if setup != Setup::A {
                    // Noisy readings (C, D) or unknown pattern changes (B, D) leave a real gap.
                    assert!(summary.gap_mean.unwrap() > 1.0, "{setup:?} {variant} {spec}: gap {:?}", summary.gap_mean);
                }
            }
        }
    }
}

#[test]
fn replayed_optimal_actions_give_the_oracles_reward_bit_for_bit() {
    for setup in SETUPS {
        for variant in VARIANTS {
            let config = LineConfig::for_setup(setup, variant);
            for seed in 42..52 {
                let best = solve(&config, seed).unwrap();
                let mut line = Line::new(config.clone(), seed);
                let mut sum = 0.0;
                for &action in &best.actions {
                    sum += line.step(action).reward;
                }
                assert!(line.truncated());
                assert_eq!(
                    (sum, line.cumulative_reward()),
                    (best.reward, best.reward),
                    "{setup:?} {variant} seed {seed}"
                );
            }
        }
    }
}

fn sorting_line(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_sorting_line")).args(args).output().expect("sorting_line runs");
    (out.status.success(), String::from_utf8(out.stdout).unwrap(), String::from_utf8(out.stderr).unwrap())
}

#[test]
fn cli_oracle_actions_replay_through_trace_and_eval_reports_the_gap() {
    for (setup, variant) in [("B", "advanced"), ("D", "basic")] {
        let (ok, stdout, stderr) =
            sorting_line(&["oracle", "--setup", setup, "--variant", variant, "--episodes", "3", "--json"]);
        assert!(ok, "{stderr}");
        let oracle: Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!((oracle["episodes"].as_u64(), oracle["seed"].as_u64()), (Some(3), Some(42)));
        let rewards: Vec<f64> =
            oracle["per_episode"].as_array().unwrap().iter().map(|e| e["reward"].as_f64().unwrap()).collect();
        let mean = rewards.iter().sum::<f64>() / 3.0;
        assert_eq!(oracle["reward_mean"].as_f64().unwrap(), mean);
        assert!(oracle["reward_std"].as_f64().unwrap() > 0.0);
        for (i, episode) in oracle["per_episode"].as_array().unwrap().iter().enumerate() {
            let actions: Vec<String> =
                episode["actions"].as_array().unwrap().iter().map(|a| a.as_u64().unwrap().to_string()).collect();
            assert_eq!(actions.len(), 50);
            let seed = (42 + i).to_string();
            let joined = actions.join(",");
            let (ok, trace, stderr) =
                sorting_line(&["trace", "--setup", setup, "--variant", variant, "--seed", &seed, "--actions", &joined]);
            assert!(ok, "{stderr}");
            let last: Value = serde_json::from_str(trace.lines().last().unwrap()).unwrap();
            assert_eq!(last["cumulative_reward"].as_f64().unwrap(), rewards[i], "{setup} {variant} seed {seed}");
            assert_eq!(last["step"]["truncated"], Value::Bool(true));
        }
        let (ok, stdout, stderr) = sorting_line(&[
            "eval",
            "--agent",
            "rba-hold",
            "--setup",
            setup,
            "--variant",
            variant,
            "--episodes",
            "3",
            "--json",
            "--gap",
        ]);
        assert!(ok, "{stderr}");
        let eval: Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(eval["oracle_mean"].as_f64().unwrap(), mean);
        let gap = eval["gap_mean"].as_f64().unwrap();
        assert!((gap - (mean - eval["reward_mean"].as_f64().unwrap())).abs() < 1e-9, "{gap}");
        assert!(eval["per_episode"][0]["gap"].as_f64().unwrap() >= 0.0);
        // Without --gap the JSON keeps exactly the fields the ROS-side evaluation reports.
        let (ok, stdout, _) = sorting_line(&[
            "eval",
            "--agent",
            "rba",
            "--setup",
            setup,
            "--variant",
            variant,
            "--episodes",
            "1",
            "--json",
        ]);
        assert!(ok && !stdout.contains("oracle") && !stdout.contains("gap"), "{stdout}");
    }
}

#[test]
fn cli_oracle_refuses_what_it_cannot_solve_naming_the_range() {
    let (ok, _, stderr) = sorting_line(&["oracle", "--setup", "A", "--variant", "advanced", "--max-steps", "5000"]);
    assert!(!ok);
    assert!(
        stderr.contains("max_steps = 5000 is out of range for the advanced oracle: allowed 1 ..= 2000"),
        "{stderr}"
    );
    let (ok, _, stderr) = sorting_line(&[
        "eval",
        "--agent",
        "rba",
        "--setup",
        "A",
        "--variant",
        "advanced",
        "--max-steps",
        "5000",
        "--gap",
    ]);
    assert!(!ok && stderr.contains("--gap: max_steps = 5000 is out of range"), "{stderr}");
    let (ok, _, stderr) = sorting_line(&["oracle", "--setup", "A", "--episodes", "0"]);
    assert!(!ok && stderr.contains("episodes = 0 is out of range"), "{stderr}");
}
