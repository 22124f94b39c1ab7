//! Offline evaluation: an agent on a line, episode by episode, with the paper's protocol
//! (episode i reset with seed S + i, reward summed over the episode, mean and population std),
//! and the clairvoyant oracle of the same episodes as the agent's ceiling (the optimality gap).
//! Pure computation; the CLI prints and draws the progress bar.

use serde::Serialize;

use crate::sim::agent::{Agent, AgentSpec};
use crate::sim::oracle;
use crate::sim::{Action, Line, LineConfig, Observation};

/// What one episode produced.
#[derive(Clone, Debug, Serialize)]
pub struct EpisodeStats {
    pub seed: u64,
    /// Sum of the step rewards.
    pub reward: f64,
    /// Mean belt speed over the steps (0.1..1.0).
    pub speed_mean: f64,
    /// Mean accuracy over the steps.
    pub accuracy_mean: f64,
    /// Container purity at the end of the episode (correct / all sorted).
    pub purity: f64,
    pub speed_changes: u32,
    /// The oracle's reward on this seed (when computed, see [`add_oracle`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub oracle: Option<f64>,
    /// `oracle - reward`: what this episode left on the table (>= 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gap: Option<f64>,
    /// The actions taken, in the Gymnasium encoding (the oracle's evaluation lists them, so that
    /// `sorting_line trace --actions` can replay them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actions: Option<Vec<usize>>,
}

/// Mean and spread over the episodes of an evaluation.
#[derive(Clone, Debug, Serialize)]
pub struct EvalSummary {
    pub agent: String,
    pub config: LineConfig,
    pub seed: u64,
    pub episodes: usize,
    pub reward_mean: f64,
    /// Population standard deviation (NumPy's `np.std`, as the reference reports).
    pub reward_std: f64,
    /// Standard error of the mean: std / sqrt(episodes).
    pub reward_se: f64,
    pub speed_mean: f64,
    pub accuracy_mean: f64,
    pub purity_mean: f64,
    pub speed_changes_mean: f64,
    /// Mean oracle reward over the same seeds (when computed, see [`add_oracle`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub oracle_mean: Option<f64>,
    /// Mean of the per-episode gaps `oracle - reward`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gap_mean: Option<f64>,
    pub per_episode: Vec<EpisodeStats>,
}

/// Runs one episode from a seeded reset until the time limit.
pub fn run_episode(line: &mut Line, agent: &mut Agent, seed: u64) -> EpisodeStats {
    agent.reseed(seed);
    run_policy(line, seed, |observation, speed| agent.act(observation, speed))
}

/// Runs one episode from a seeded reset, asking `policy(observation, current speed index)` for
/// each action.
fn run_policy(line: &mut Line, seed: u64, mut policy: impl FnMut(Observation, usize) -> Action) -> EpisodeStats {
    let mut observation = line.reset(Some(seed));
    let (mut reward, mut speed, mut accuracy, mut steps) = (0.0, 0.0, 0.0, 0u32);
    loop {
        let action = policy(observation, line.speed_index());
        let out = line.step(action);
        reward += out.reward;
        speed += action.speed();
        accuracy += out.accuracy;
        steps += 1;
        observation = out.observation;
        if out.truncated || out.terminated {
            break;
        }
    }
    EpisodeStats {
        seed,
        reward,
        speed_mean: speed / f64::from(steps),
        accuracy_mean: accuracy / f64::from(steps),
        purity: line.containers().purity(),
        speed_changes: line.speed_changes(),
        oracle: None,
        gap: None,
        actions: None,
    }
}

fn mean(values: impl Iterator<Item = f64>, n: usize) -> f64 {
    values.sum::<f64>() / n as f64
}

fn check_episodes(config: &LineConfig, episodes: usize) -> Result<(), String> {
    if episodes == 0 {
        return Err("episodes = 0 is out of range: allowed 1 or more".into());
    }
    config.validate().map_err(|e| e.to_string())
}

/// Evaluates `spec` over `episodes` episodes seeded `seed`, `seed + 1`, ...; `progress` is called
/// after each episode.
pub fn evaluate(
    config: &LineConfig,
    spec: AgentSpec,
    episodes: usize,
    seed: u64,
    mut progress: impl FnMut(&EpisodeStats),
) -> Result<EvalSummary, String> {
    check_episodes(config, episodes)?;
    let mut agent = Agent::new(spec, config, seed)?;
    let mut line = Line::new(config.clone(), seed);
    let mut per_episode = Vec::with_capacity(episodes);
    for i in 0..episodes as u64 {
        let stats = run_episode(&mut line, &mut agent, seed + i);
        progress(&stats);
        per_episode.push(stats);
    }
    Ok(summarize(spec.to_string(), config, seed, per_episode))
}

/// The clairvoyant oracle (`sim::oracle`) over the episodes `evaluate` would run: each episode's
/// optimal actions are replayed through the line, which must give exactly the oracle's reward
/// (an error otherwise: the oracle's model of the line would be out of date).
pub fn evaluate_oracle(
    config: &LineConfig,
    episodes: usize,
    seed: u64,
    mut progress: impl FnMut(&EpisodeStats),
) -> Result<EvalSummary, String> {
    check_episodes(config, episodes)?;
    let mut line = Line::new(config.clone(), seed);
    let mut per_episode = Vec::with_capacity(episodes);
    for i in 0..episodes as u64 {
        let best = oracle::solve(config, seed + i)?;
        let mut next = best.actions.iter().copied();
        let mut stats = run_policy(&mut line, seed + i, |_, _| next.next().expect("one action per step"));
        if stats.reward != best.reward {
            return Err(format!(
                "the oracle's actions for seed {} replay to {} on the line, not its {}: the oracle's model of the line is out of date",
                seed + i,
                stats.reward,
                best.reward
            ));
        }
        stats.actions = Some(best.actions.iter().map(|a| a.to_discrete(config.variant)).collect());
        progress(&stats);
        per_episode.push(stats);
    }
    Ok(summarize("oracle".into(), config, seed, per_episode))
}

/// Adds the oracle's reward and the gap to every episode of `summary` and their means.
pub fn add_oracle(summary: &mut EvalSummary) -> Result<(), String> {
    for episode in &mut summary.per_episode {
        let best = oracle::solve(&summary.config, episode.seed)?.reward;
        episode.oracle = Some(best);
        episode.gap = Some(best - episode.reward);
    }
    let n = summary.episodes;
    summary.oracle_mean = Some(mean(summary.per_episode.iter().filter_map(|e| e.oracle), n));
    summary.gap_mean = Some(mean(summary.per_episode.iter().filter_map(|e| e.gap), n));
    Ok(())
}

fn summarize(agent: String, config: &LineConfig, seed: u64, per_episode: Vec<EpisodeStats>) -> EvalSummary {
    let n = per_episode.len();
    let reward_mean = mean(per_episode.iter().map(|e| e.reward), n);
    let reward_std = mean(per_episode.iter().map(|e| (e.reward - reward_mean).powi(2)), n).sqrt();
    EvalSummary {
        agent,
        config: config.clone(),
        seed,
        episodes: n,
        reward_mean,
        reward_std,
        reward_se: reward_std / (n as f64).sqrt(),
        speed_mean: mean(per_episode.iter().map(|e| e.speed_mean), n),
        accuracy_mean: mean(per_episode.iter().map(|e| e.accuracy_mean), n),
        purity_mean: mean(per_episode.iter().map(|e| e.purity), n),
        speed_changes_mean: mean(per_episode.iter().map(|e| f64::from(e.speed_changes)), n),
        oracle_mean: None,
        gap_mean: None,
        per_episode,
    }
}
