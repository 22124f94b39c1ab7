"""`sorting-line-transfer`: the transfer study of the evolving line (issue 16; the paper's future
work), through ROS: MaskablePPO on `SortingLineEvolving-v0`.

For each scenario and training seed:
- **continued** (a): one agent trains on the line before the change for `--before` episodes and
  goes on training, unchanged, after it for `--after` episodes (the change is in the schedule:
  the agent is not told);
- **frozen** (b): that agent's snapshot at the change, evaluated on the changed line without
  further learning (before the machine upgrade its masks allow mode 0 only, and so they stay:
  "frozen with mode 0");
- **scratch** (c): a new agent trained on the changed line from the start for `--after` episodes;
- the rule-based agents `rba` and `rba-hold` on the line before and after (`sorting_line eval`,
  offline, same seeds).

Scenarios: `upgrade` (basic B -> advanced B: machine and sensor upgrade, the paper's) and
`drift` (B with sensor noise 0 -> 0.3 and threshold 0.7 -> 0.8 in three steps). The schedules are
the ready ones in `evolutions/`, with the change moved to episode `--before` + 1.

Reported: reward per episode around the change (training episodes of (a) and (c), evaluation
episodes of (b)), each agent's final reward, and the steps (a) and (c) need after the change to
reach 90 % of (c)'s final reward (10-episode moving mean). Writes `transfer.json`, `transfer.md`
(the table) and `transfer.png` / `transfer.svg` (the curves) to `--out`.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

EPISODE_STEPS = 50
SCENARIOS = ("upgrade", "drift")
WINDOW = 10  # episodes of the moving mean


def schedules(scenario: str, before: int, out: Path) -> tuple[Path, Path]:
    """(the evolving schedule with the change after `before` episodes, the changed line's schedule
    from episode 0), written to `out`, from the ready schedule of `scenario`."""
    from ..envs.evolving import schedule_file

    events = yaml.safe_load(schedule_file(scenario).read_text())["events"]
    changes = sorted({e["at"]["episode"] for e in events if e["at"].get("episode", 0) > 0})
    first = changes[0]
    evolving, final = [], {}
    for e in events:
        e = dict(e)
        episode = e["at"]["episode"]
        if episode > 0:
            # The first change lands at before + 1; later ones keep their spacing, scaled to 1/20.
            e["at"] = {"episode": before + 1 + (episode - first) // 20}
        evolving.append(e)
        final.update({k: v for k, v in e.items() if k != "at"})
    a = out / f"{scenario}-at-{before + 1}.yaml"
    b = out / f"{scenario}-after.yaml"
    a.write_text(yaml.safe_dump({"events": evolving}, sort_keys=False))
    b.write_text(yaml.safe_dump({"events": [{"at": {"episode": 0}, **final}]}, sort_keys=False))
    return a, b


def make_env(schedule: Path, setup: str):
    import gymnasium
    from stable_baselines3.common.monitor import Monitor

    import sorting_line_gym  # noqa: F401 - registers the ids

    env = gymnasium.make("sorting_line_gym:SortingLineEvolving-v0", evolution=str(schedule), setup=setup,
                         max_episode_steps=EPISODE_STEPS, step_timeout=10.0)
    return Monitor(env)


def new_model(env, seed: int):
    from sb3_contrib import MaskablePPO

    return MaskablePPO("MlpPolicy", env, n_steps=10 * EPISODE_STEPS, batch_size=100, n_epochs=5, seed=seed,
                       device="cpu", verbose=0)


def evaluate(model, env, episodes: int, seed: int, mode0: bool) -> list[float]:
    """Deterministic episodes of `model` on `env` (seeds seed, seed+1, ...); `mode0`: the masks of a
    machine without sort modes, whatever the line has."""
    rewards = []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        total, done = 0.0, False
        while not done:
            masks = env.get_wrapper_attr("action_masks")()
            if mode0:
                masks = np.array([a % 3 == 0 for a in range(len(masks))])
            action, _ = model.predict(obs, action_masks=masks, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(int(action))
            total += reward
            done = terminated or truncated
        rewards.append(total)
    return rewards


def rule_based(setup: str, variant: str, schedule: Path | None, episodes: int, seed: int) -> dict[str, float]:
    from ..line.process import find_node_binary

    out = {}
    for agent in ("rba", "rba-hold"):
        argv = [find_node_binary(), "eval", "--agent", agent, "--setup", setup, "--variant", variant,
                "--episodes", str(episodes), "--seed", str(seed), "--json"]
        if schedule is not None:
            argv += ["--evolution", str(schedule)]
        r = subprocess.run(argv, capture_output=True, text=True, check=True, timeout=120)
        out[agent] = json.loads(r.stdout)["reward_mean"]
    return out


def recovery_steps(curve: list[float], target: float) -> int | None:
    """Steps until the moving mean of `curve` (episode rewards) first reaches `target`."""
    for k in range(len(curve)):
        window = curve[max(0, k - WINDOW + 1): k + 1]
        if len(window) == min(WINDOW, k + 1) and np.mean(window) >= target and k + 1 >= WINDOW:
            return (k + 1) * EPISODE_STEPS
    return None


def run_seed(scenario: str, seed: int, before: int, after: int, evaluations: int, out: Path, log) -> dict:
    evolving, changed = schedules(scenario, before, out)
    setup = "B"
    started = time.monotonic()
    env = make_env(evolving, setup)
    model = new_model(env, seed)
    model.learn(before * EPISODE_STEPS)
    snapshot = out / f"{scenario}-seed{seed}-before.zip"
    model.save(snapshot)
    log(f"{scenario} seed {seed}: trained {before} episodes before the change ({time.monotonic() - started:.0f} s)")
    model.learn(after * EPISODE_STEPS, reset_num_timesteps=False)
    continued = [float(r) for r in env.get_episode_rewards()]
    env.close()
    log(f"{scenario} seed {seed}: continued {after} episodes after it ({time.monotonic() - started:.0f} s)")

    from sb3_contrib import MaskablePPO

    eval_env = make_env(changed, setup)
    frozen_model = MaskablePPO.load(snapshot, device="cpu")
    mode0 = scenario == "upgrade"
    frozen = evaluate(frozen_model, eval_env, evaluations, 10_000, mode0)
    continued_final = evaluate(model, eval_env, evaluations, 10_000, False)
    eval_env.close()

    env = make_env(changed, setup)
    scratch_model = new_model(env, seed)
    scratch_model.learn(after * EPISODE_STEPS)
    scratch = [float(r) for r in env.get_episode_rewards()]
    env.close()
    scratch_env = make_env(changed, setup)
    scratch_final = evaluate(scratch_model, scratch_env, evaluations, 10_000, False)
    scratch_env.close()
    log(f"{scenario} seed {seed}: scratch {after} episodes, evaluations done ({time.monotonic() - started:.0f} s)")

    target = 0.9 * float(np.mean(scratch_final))
    after_change = continued[before:]
    return {
        "scenario": scenario, "seed": seed, "before": before, "after": after,
        "continued_curve": continued, "scratch_curve": scratch, "frozen_eval": frozen,
        "continued_eval": continued_final, "scratch_eval": scratch_final,
        "target_90": target,
        "continued_recovery_steps": recovery_steps(after_change, target),
        "scratch_recovery_steps": recovery_steps(scratch, target),
        "seconds": time.monotonic() - started,
    }


def moving(curve, window=WINDOW):
    c = np.asarray(curve, dtype=float)
    return np.array([c[max(0, k - window + 1): k + 1].mean() for k in range(len(c))])


def plot(results: list[dict], baselines: dict, out: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.5))
    axes = fig.subplots(1, len(SCENARIOS))
    for ax, scenario in zip(np.atleast_1d(axes), SCENARIOS, strict=False):
        runs = [r for r in results if r["scenario"] == scenario]
        if not runs:
            continue
        before = runs[0]["before"]
        for i, r in enumerate(runs):
            x = np.arange(len(r["continued_curve"])) - before
            ax.plot(x, moving(r["continued_curve"]), color="tab:blue", alpha=0.8,
                    label="(a) continued" if i == 0 else None)
            xs = np.arange(len(r["scratch_curve"]))
            ax.plot(xs, moving(r["scratch_curve"]), color="tab:orange", alpha=0.8,
                    label="(c) from scratch (after the change)" if i == 0 else None)
        frozen = np.mean([np.mean(r["frozen_eval"]) for r in runs])
        ax.axhline(frozen, color="tab:gray", ls="--", label=f"(b) frozen at the change: {frozen:.1f}")
        for agent, style in (("rba-hold", ":"), ("rba", "-.")):
            value = baselines[scenario]["after"][agent]
            ax.axhline(value, color="tab:green", ls=style, label=f"{agent} after the change: {value:.1f}")
        ax.axvline(0, color="black", lw=0.8)
        ax.set_title(f"{scenario}: change after {before} episodes ({len(runs)} seeds)")
        ax.set_xlabel("episodes relative to the change (50 steps each)")
        ax.set_ylabel(f"episode reward ({WINDOW}-episode moving mean)")
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "transfer.png", dpi=110)
    fig.savefig(out / "transfer.svg")


def table(results: list[dict], baselines: dict) -> str:
    def ms(values):
        values = [v for v in values if v is not None]
        if not values:
            return "not reached"
        return f"{np.mean(values):.2f} +- {np.std(values):.2f}" if len(values) > 1 else f"{values[0]:.2f}"

    lines = ["| scenario | seeds | (a) continued, final | (b) frozen | (c) scratch, final | rba-hold before / after | "
             "rba before / after | steps to 90 % of (c): (a) | (c) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for scenario in SCENARIOS:
        runs = [r for r in results if r["scenario"] == scenario]
        if not runs:
            continue
        b = baselines[scenario]

        def steps(key, runs=runs):
            got = [r[key] for r in runs]
            reached = [g for g in got if g is not None]
            text = f"{np.mean(reached):.0f}" if reached else "-"
            return f"{text} ({len(reached)}/{len(got)} reached)"

        lines.append(
            f"| {scenario} | {len(runs)} | {ms([np.mean(r['continued_eval']) for r in runs])} | "
            f"{ms([np.mean(r['frozen_eval']) for r in runs])} | {ms([np.mean(r['scratch_eval']) for r in runs])} | "
            f"{b['before']['rba-hold']:.2f} / {b['after']['rba-hold']:.2f} | "
            f"{b['before']['rba']:.2f} / {b['after']['rba']:.2f} | "
            f"{steps('continued_recovery_steps')} | {steps('scratch_recovery_steps')} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sorting-line-transfer", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", nargs="+", choices=SCENARIOS, default=list(SCENARIOS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--before", type=int, default=200, help="episodes before the change (default 200)")
    parser.add_argument("--after", type=int, default=200, help="episodes after it, and from scratch (default 200)")
    parser.add_argument("--evaluations", type=int, default=20, help="evaluation episodes (seeds 10000...)")
    parser.add_argument("--out", type=Path, default=Path("results/transfer"))
    parser.add_argument("--torch-threads", type=int, default=1)
    parser.add_argument("--report-only", action="store_true",
                        help="train nothing: table and plot of the runs already in OUT/transfer.json")
    args = parser.parse_args(argv)
    if args.before < 1 or args.after < WINDOW:
        parser.error(f"--before must be >= 1 and --after >= {WINDOW}")
    import torch

    torch.set_num_threads(args.torch_threads)
    args.out.mkdir(parents=True, exist_ok=True)
    def log(text):
        return print(f"[{time.strftime('%H:%M:%S')}] {text}", flush=True)
    results_file = args.out / "transfer.json"
    done = json.loads(results_file.read_text()) if results_file.exists() else {"runs": []}
    runs = [r for r in done["runs"] if r["before"] == args.before and r["after"] == args.after]
    baselines = done.get("baselines", {})
    for scenario in args.scenarios:
        if args.report_only:
            continue
        evolving, changed = schedules(scenario, args.before, args.out)
        # Before: basic B for the upgrade, advanced B for the drift; after: the changed line.
        before_variant = "basic" if scenario == "upgrade" else "advanced"
        baselines[scenario] = {
            "before": rule_based("B", before_variant, None, args.evaluations, 10_000),
            "after": rule_based("B", "advanced", changed, args.evaluations, 10_000),
        }
        for seed in args.seeds:
            if any(r["scenario"] == scenario and r["seed"] == seed for r in runs):
                log(f"{scenario} seed {seed}: in {results_file} already (resumed)")
                continue
            runs.append(run_seed(scenario, seed, args.before, args.after, args.evaluations, args.out, log))
            results_file.write_text(json.dumps({"runs": runs, "baselines": baselines}, indent=1))
    results_file.write_text(json.dumps({"runs": runs, "baselines": baselines}, indent=1))
    chosen = [r for r in runs if r["scenario"] in args.scenarios and (args.report_only or r["seed"] in args.seeds)]
    plot(chosen, baselines, args.out)
    text = table(chosen, baselines)
    (args.out / "transfer.md").write_text(text + "\n")
    print(text)
    log(f"wrote {results_file}, {args.out / 'transfer.md'}, {args.out / 'transfer.png'} and .svg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
