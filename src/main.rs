//! The `sorting_line` command line: `eval`, `oracle`, `table`, `policy`, `trace` and `vocabulary`
//! run the simulation library offline, `node` runs the line as a ROS 2 node (the `ros` feature,
//! on by default; without it the command does not exist).

use std::io::{self, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use sorting_line::eval::{add_oracle, evaluate, evaluate_oracle, EvalSummary};
#[cfg(feature = "ros")]
use sorting_line::ros::options::NodeArgs;
use sorting_line::sim::agent::AgentSpec;
use sorting_line::sim::config::{EPISODE_STEPS, EVAL_EPISODES, EVAL_FIRST_SEED};
use sorting_line::sim::evolution::{category_code, At, Schedule};
use sorting_line::sim::material::SORT_MODES;
use sorting_line::sim::rba::{analysis_table, ANALYSIS_COLUMNS};
use sorting_line::sim::{LineConfig, Setup, Variant};

#[derive(Parser)]
#[command(name = "sorting_line", version, about = "The SortingEnv sorting line: simulation, evaluation and ROS 2 node")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Evaluate an agent offline on the simulation library (no ROS); `--gap` adds the oracle.
    Eval(EvalArgs),
    /// The clairvoyant optimum of each episode seed: the highest reward any action sequence
    /// reaches knowing the seed's random streams (the ceiling for the optimality gap).
    Oracle(OracleArgs),
    /// Print the expected-reward analysis behind the rule-based agent as CSV.
    Table(TableArgs),
    /// Print the decision tables of `rba` and `rba-hold` for a setup as one JSON object (what a
    /// controller outside this library, e.g. the Python one, decides with).
    Policy(PolicyArgs),
    /// Run the line as a ROS 2 node.
    #[cfg(feature = "ros")]
    Node(NodeArgs),
    /// Print the library's trajectory for a seed and an action list, one JSON object per step
    /// (the reference other paths are compared with).
    Trace(TraceArgs),
    /// Print the line's vocabulary as one JSON object: setups, variants, inputs, speeds, sort
    /// modes, start speed, threshold and episode lengths, and the node's topics, services and
    /// actions (what other languages' copies are checked against).
    Vocabulary,
}

#[derive(Args)]
struct TraceArgs {
    /// The paper's setup: A (random), B (seasonal, penalty 0.5), C (random, noise 0.3), D (both).
    #[arg(long)]
    setup: Setup,
    /// The line: basic (belt speed only) or advanced (speed and sort mode, ratio sensor).
    #[arg(long, default_value = "basic")]
    variant: Variant,
    /// Seed of the first episode (its random streams); `r<N>` in --actions reseeds.
    #[arg(long, default_value_t = 42)]
    seed: u64,
    /// Steps per episode: the line reports `truncated` at the last one.
    #[arg(long, default_value_t = EPISODE_STEPS)]
    max_steps: u32,
    // The help states `Action::to_discrete`'s encoding, its factor the library's mode count.
    #[arg(long, value_delimiter = ',', help = actions_help())]
    actions: Vec<String>,
    /// An evolution schedule (YAML, see docs/evolving.md): each JSON line then also carries `tick`,
    /// the `evolution` events applied there, the line's `settings` and its `category_reading`
    /// (3 = unknown: no ratio sensor).
    #[arg(long, value_name = "FILE")]
    evolution: Option<PathBuf>,
}

/// `trace --actions`' help: the Gymnasium encoding of an action (`Action::to_discrete`), its
/// factor the library's count of sort modes.
fn actions_help() -> String {
    let advanced = format!("speed index * {} + mode", SORT_MODES.len());
    format!(
        "Comma-separated Gymnasium actions (basic: speed index; advanced: {advanced}); `r` resets without a \
         seed, `r<N>` resets with seed N. With --evolution, actions are always advanced ones ({advanced}), as \
         SortingLineEvolving-v0 takes them"
    )
}

/// The episodes `eval` and `oracle` run: episode i is reset with seed SEED + i.
#[derive(Args)]
struct EpisodeArgs {
    /// The paper's setup: A (random), B (seasonal, penalty 0.5), C (random, noise 0.3), D (both).
    #[arg(long)]
    setup: Setup,
    /// The line: basic (belt speed only) or advanced (speed and sort mode, ratio sensor).
    #[arg(long, default_value = "basic")]
    variant: Variant,
    /// Number of episodes; episode i is reset with seed SEED + i.
    #[arg(long, default_value_t = EVAL_EPISODES)]
    episodes: usize,
    /// Seed of episode 0 (SEED); episode i uses SEED + i.
    #[arg(long, default_value_t = EVAL_FIRST_SEED)]
    seed: u64,
    /// Steps per episode (the advanced oracle: at most 2000).
    #[arg(long, default_value_t = EPISODE_STEPS)]
    max_steps: u32,
    /// Print one JSON object instead of a summary.
    #[arg(long)]
    json: bool,
    /// An evolution schedule (YAML, see docs/evolving.md): the line evolves across the episodes
    /// (episode k of the evaluation is the line's episode k).
    #[arg(long, value_name = "FILE")]
    evolution: Option<PathBuf>,
}

impl EpisodeArgs {
    fn config(&self) -> LineConfig {
        LineConfig { max_steps: self.max_steps, ..LineConfig::for_setup(self.setup, self.variant) }
    }
}

#[derive(Args)]
struct EvalArgs {
    /// rba, rba-hold, bayes, random, constant:K, constant:K:cat or constant:K:M (K = 0..9, M = 0..2).
    #[arg(long)]
    agent: AgentSpec,
    #[command(flatten)]
    run: EpisodeArgs,
    /// Also solve the clairvoyant oracle of each episode seed and report it and the agent's gap
    /// to it (`oracle_mean`, `gap_mean`; `oracle`, `gap` per episode).
    #[arg(long)]
    gap: bool,
}

#[derive(Args)]
struct OracleArgs {
    #[command(flatten)]
    run: EpisodeArgs,
    /// Also print each episode's optimal actions, ready for `sorting_line trace --actions`
    /// (`--json` always lists them).
    #[arg(long)]
    actions: bool,
}

#[derive(Args)]
struct PolicyArgs {
    /// The paper's setup: A (random), B (seasonal, penalty 0.5), C (random, noise 0.3), D (both).
    #[arg(long)]
    setup: Setup,
    /// The line: basic (belt speed only) or advanced (speed and sort mode, ratio sensor).
    #[arg(long, default_value = "basic")]
    variant: Variant,
}

#[derive(Args)]
struct TableArgs {
    /// The line: basic (belt speed only) or advanced (speed and sort mode, ratio sensor).
    #[arg(long, default_value = "basic")]
    variant: Variant,
    /// Accuracy threshold of the reward.
    #[arg(long, default_value_t = LineConfig::default().threshold)]
    threshold: f64,
}

fn main() -> ExitCode {
    // The DDS stack's own log (RUST_LOG=rustdds=debug) is set up by the node (ros::node::log).
    // `--ros-args ... [--]` belongs to ROS, not to clap: split it off first.
    #[cfg(feature = "ros")]
    let (args, ros_args) = sorting_line::ros::options::split_ros_args(std::env::args().collect());
    #[cfg(not(feature = "ros"))]
    let args = std::env::args();
    let cli = Cli::parse_from(args);
    let result = match cli.command {
        Command::Eval(args) => run_eval(args),
        Command::Oracle(args) => run_oracle(args),
        Command::Table(args) => run_table(args),
        Command::Policy(args) => run_policy(args),
        #[cfg(feature = "ros")]
        Command::Node(args) => sorting_line::ros::run(args, ros_args),
        Command::Trace(args) => run_trace(args),
        Command::Vocabulary => run_vocabulary(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("sorting_line: {message}");
            ExitCode::from(2)
        }
    }
}

/// Reads and validates `--evolution FILE` (none: the empty schedule).
fn load_evolution(file: Option<&Path>) -> Result<Schedule, String> {
    let Some(file) = file else { return Ok(Schedule::default()) };
    let text = std::fs::read_to_string(file).map_err(|e| format!("--evolution {}: {e}", file.display()))?;
    Schedule::from_yaml(&text).map_err(|e| format!("--evolution {}: {e}", file.display()))
}

fn run_eval(args: EvalArgs) -> Result<(), String> {
    let run = &args.run;
    let config = run.config();
    let evolution = load_evolution(run.evolution.as_deref())?;
    if args.gap && !evolution.is_empty() {
        return Err("--gap: the oracle models a fixed line; it cannot be used with --evolution".into());
    }
    let bar = if io::stderr().is_terminal() && run.episodes >= 20 {
        let bar = ProgressBar::new(run.episodes as u64);
        bar.set_style(
            ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} episodes, {per_sec}, eta {eta}")
                .expect("a valid template"),
        );
        bar.set_message(format!("{} on {:?} {}", args.agent, run.setup, run.variant));
        bar
    } else {
        ProgressBar::hidden()
    };
    let mut summary = evaluate(&config, &evolution, args.agent, run.episodes, run.seed, |_| bar.inc(1))?;
    bar.finish_and_clear();
    if args.gap {
        add_oracle(&mut summary).map_err(|e| format!("--gap: {e}"))?;
    }
    let mut out = io::stdout().lock();
    if run.json {
        print_json(&mut out, &summary)
    } else {
        print_summary(&mut out, run.setup, &summary).map_err(|e| e.to_string())
    }
}

fn print_json(out: &mut impl Write, summary: &EvalSummary) -> Result<(), String> {
    serde_json::to_writer(&mut *out, summary).map_err(|e| e.to_string())?;
    writeln!(out).map_err(|e| e.to_string())
}

fn run_oracle(args: OracleArgs) -> Result<(), String> {
    let run = &args.run;
    if run.evolution.is_some() {
        return Err("--evolution: the oracle models a fixed line; it cannot solve an evolving one".into());
    }
    let started = std::time::Instant::now();
    let summary = evaluate_oracle(&run.config(), run.episodes, run.seed, |_| {})?;
    let elapsed = started.elapsed().as_secs_f64();
    let mut out = io::stdout().lock();
    if run.json {
        return print_json(&mut out, &summary);
    }
    let write = |out: &mut io::StdoutLock| -> io::Result<()> {
        print_summary(out, run.setup, &summary)?;
        writeln!(
            out,
            "solved in     {:.1} ms ({:.3} ms per episode, replays checked)",
            elapsed * 1e3,
            elapsed * 1e3 / summary.episodes as f64
        )?;
        if args.actions {
            for e in &summary.per_episode {
                let actions: Vec<String> = e.actions.iter().flatten().map(usize::to_string).collect();
                writeln!(out, "seed {} reward {} actions {}", e.seed, e.reward, actions.join(","))?;
            }
        }
        Ok(())
    };
    write(&mut out).map_err(|e| e.to_string())
}

fn print_summary(out: &mut impl Write, setup: Setup, s: &EvalSummary) -> io::Result<()> {
    writeln!(
        out,
        "agent {} | setup {:?} {} | {} episodes from seed {}",
        s.agent, setup, s.config.variant, s.episodes, s.seed
    )?;
    writeln!(
        out,
        "reward        {:.2} +- {:.2} (std; standard error {:.2})",
        s.reward_mean, s.reward_std, s.reward_se
    )?;
    writeln!(out, "mean speed    {:.1} %", s.speed_mean * 100.0)?;
    writeln!(out, "mean accuracy {:.3}", s.accuracy_mean)?;
    writeln!(out, "purity        {:.1} %", s.purity_mean * 100.0)?;
    writeln!(out, "speed changes {:.1} per episode", s.speed_changes_mean)?;
    if let (Some(oracle), Some(gap)) = (s.oracle_mean, s.gap_mean) {
        writeln!(out, "oracle        {oracle:.2} (mean gap to the agent {gap:.2})")?;
    }
    if !s.evolution.is_empty() {
        let episodes: Vec<String> = s
            .per_episode
            .iter()
            .enumerate()
            .filter(|(_, e)| !e.evolution_events.is_empty())
            .map(|(k, e)| format!("{} (events {:?})", k + 1, e.evolution_events))
            .collect();
        let applied = if episodes.is_empty() { "none in these episodes".to_string() } else { episodes.join(", ") };
        writeln!(out, "evolution     {} events; applied in episode {applied}", s.evolution.events.len())?;
    }
    Ok(())
}

fn run_table(args: TableArgs) -> Result<(), String> {
    let rows = analysis_table(args.variant, args.threshold).map_err(|e| e.to_string())?;
    let mut out = io::stdout().lock();
    let write = |out: &mut io::StdoutLock| -> io::Result<()> {
        writeln!(out, "{}", ANALYSIS_COLUMNS.join(","))?;
        for r in &rows {
            writeln!(out, "{}", r.fields().join(","))?;
        }
        Ok(())
    };
    write(&mut out).map_err(|e| e.to_string())
}

/// `{"setup", "variant", "levels": 101, "rba": [[speed_index, mode]; cell], "rba_hold":
/// [[[speed_index, mode]; current speed 0..9]; cell], "config"}` with `cell = level * 3 + category`
/// and `level = round(reading * 100)` clamped to 0..=100 (`observation::level`). The basic line
/// decides from category slot 0.
fn run_policy(args: PolicyArgs) -> Result<(), String> {
    let policy = sorting_line::sim::rba::policy(args.setup, args.variant);
    let mut out = io::stdout().lock();
    writeln!(out, "{policy}").map_err(|e| e.to_string())
}

fn run_trace(args: TraceArgs) -> Result<(), String> {
    use sorting_line::sim::{Action, Line};
    let config = LineConfig { max_steps: args.max_steps, ..LineConfig::for_setup(args.setup, args.variant) };
    config.validate().map_err(|e| e.to_string())?;
    let evolution = load_evolution(args.evolution.as_deref())?;
    let evolving = args.evolution.is_some();
    // The evolving line takes advanced actions throughout (its modes may come and go).
    let encoding = if evolving { Variant::Advanced } else { args.variant };
    let mut line = Line::with_evolution(config, args.seed, evolution);
    let mut out = io::stdout().lock();
    let mut emit = |value: serde_json::Value| writeln!(out, "{value}").map_err(|e| e.to_string());
    // What an evolving line adds to a record: the events applied at `at`, and the line now.
    let evolution_fields = |line: &Line, at: At, record: &mut serde_json::Value| {
        if evolving {
            let applied: Vec<serde_json::Value> = line
                .evolution()
                .events_at(at)
                .map(|(index, event)| {
                    let mut e = serde_json::to_value(event).expect("an event serialises");
                    e["index"] = index.into();
                    e
                })
                .collect();
            record["tick"] = line.tick().into();
            record["evolution"] = applied.into();
            record["settings"] = serde_json::to_value(line.settings()).expect("settings serialise");
            record["category_reading"] = category_code(line.category_reading()).into();
        }
    };
    let reset_record = |line: &Line| {
        let mut record = serde_json::json!({"reset": {"seed": line.seed(), "episode": line.episode(), "observation": line.observation()}});
        evolution_fields(line, At::Episode(line.episode()), &mut record);
        record
    };
    emit(reset_record(&line))?;
    for token in &args.actions {
        if let Some(seed) = token.strip_prefix('r') {
            let seed = if seed.is_empty() {
                None
            } else {
                Some(seed.parse::<u64>().map_err(|_| format!("bad reset '{token}'"))?)
            };
            line.reset(seed);
            emit(reset_record(&line))?;
            continue;
        }
        let action = token
            .parse::<usize>()
            .ok()
            .and_then(|a| Action::from_discrete(encoding, a))
            .ok_or_else(|| format!("action '{token}' is out of range for the {} line", encoding))?;
        let tick = line.tick();
        let outcome = line.step(action);
        let c = line.containers();
        let mut record = serde_json::json!({
            "step": outcome, "episode": line.episode(), "cumulative_reward": line.cumulative_reward(),
            "containers": c, "purity": c.purity(), "speed_changes": line.speed_changes(),
        });
        evolution_fields(&line, At::Tick(tick), &mut record);
        // `tick` of a step record is the tick the step was (the line's counter is past it now).
        if evolving {
            record["tick"] = tick.into();
        }
        emit(record)?;
    }
    Ok(())
}

/// `{"variants", "inputs", "setups": {name: {input, obs_noise, action_penalty}}, "speeds",
/// "start_speed_index", "modes"/"categories": {name: number}, "threshold", "episode_steps",
/// "max_episode_steps", "node_lines"}`, every value taken from the library's own constants; with the node (the
/// `ros` feature) also its endpoints, `"topics"` and `"qos_profiles"` (`ros::topics::vocabulary`).
fn run_vocabulary() -> Result<(), String> {
    use sorting_line::sim::config::{INPUT_KINDS, MAX_EPISODE_STEPS, MAX_NODE_LINES, SETUPS, VARIANTS};
    use sorting_line::sim::material::{CATEGORIES, SORT_MODES};
    use sorting_line::sim::speed::{SPEEDS, START_SPEED_INDEX};
    let setups: serde_json::Map<String, serde_json::Value> = SETUPS
        .iter()
        .map(|&s| {
            let c = LineConfig::for_setup(s, Variant::Basic);
            let value =
                serde_json::json!({"input": c.input, "obs_noise": c.obs_noise, "action_penalty": c.action_penalty});
            (s.to_string(), value)
        })
        .collect();
    // name -> wire number, the name as serde writes it (the form of `trace` and parameter files).
    fn numbered<T: serde::Serialize>(values: impl Iterator<Item = (T, usize)>) -> serde_json::Value {
        let map: serde_json::Map<String, serde_json::Value> = values
            .map(|(v, i)| (serde_json::json!(v).as_str().unwrap_or_default().to_owned(), serde_json::json!(i)))
            .collect();
        map.into()
    }
    let modes = numbered(SORT_MODES.iter().map(|&m| (m, m.index())));
    let categories = numbered(CATEGORIES.iter().map(|&c| (c, c.index())));
    let defaults = LineConfig::default();
    // `mut` only for the node's endpoints below, which a build without the ros feature leaves out.
    #[cfg_attr(not(feature = "ros"), allow(unused_mut))]
    let mut vocabulary = serde_json::json!({
        "variants": VARIANTS,
        "inputs": INPUT_KINDS,
        "setups": setups,
        "speeds": SPEEDS,
        "start_speed_index": START_SPEED_INDEX,
        "modes": modes,
        "categories": categories,
        "threshold": defaults.threshold,
        "episode_steps": defaults.max_steps,
        "max_episode_steps": MAX_EPISODE_STEPS,
        "node_lines": MAX_NODE_LINES,
        "category_unknown_code": sorting_line::sim::evolution::CATEGORY_UNKNOWN_CODE,
        "category_unknown_observation": sorting_line::sim::evolution::CATEGORY_UNKNOWN_OBSERVATION,
    });
    // The node's endpoints (`ros::topics`: "topics" and "qos_profiles"), with the node only.
    #[cfg(feature = "ros")]
    if let (Some(all), serde_json::Value::Object(topics)) =
        (vocabulary.as_object_mut(), sorting_line::ros::topics::vocabulary())
    {
        all.extend(topics);
    }
    let mut out = io::stdout().lock();
    writeln!(out, "{vocabulary}").map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// Every option and argument of every subcommand says what it is for in `--help`.
    #[test]
    fn every_flag_has_help_text() {
        fn walk(command: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for arg in command.get_arguments() {
                let generated = matches!(arg.get_id().as_str(), "help" | "version");
                if !generated && arg.get_help().is_none() && arg.get_long_help().is_none() {
                    missing.push(format!("{path} --{}", arg.get_long().unwrap_or(arg.get_id().as_str())));
                }
            }
            for sub in command.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let mut command = Cli::command();
        command.build();
        let mut missing = Vec::new();
        walk(&command, "sorting_line", &mut missing);
        assert!(missing.is_empty(), "flags without help text: {missing:?}");
        let subcommands: Vec<&str> = command.get_subcommands().map(|c| c.get_name()).collect();
        // `node` exists with the ros feature (the default) only; clap adds `help`.
        let ros = cfg!(feature = "ros");
        assert_eq!(subcommands.contains(&"node"), ros, "{subcommands:?}");
        assert!(subcommands.len() >= if ros { 7 } else { 6 }, "{subcommands:?}");
    }
}
