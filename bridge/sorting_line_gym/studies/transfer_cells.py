"""The cells of the transfer study (`sorting-line-transfer`): what each one trains and evaluates.

A cell is saved as soon as it finishes (``studies.cell_store``), so a stopped study resumes cell
by cell. The scenarios (``SCENARIOS``) are the ready schedules of ``evolutions/`` of the same name;
``line_states`` says what each one's line is before and after its change. The cells of a scenario:

- ``baselines``: `rba`, `rba-hold` and `random` on the line before and after the change, and the
  oracle (`sorting_line oracle`, the clairvoyant optimum per seed) of each side: random and the
  oracle are the lower and upper references of the report's normalised curves;
- ``transfer`` per algorithm and training seed: one agent trained ``before`` episodes on the
  evolving line and ``after`` more past the change (strategy **continued**), and its snapshot at
  the change (strategy **frozen**), both evaluated on the changed line;
- ``scratch`` per algorithm and training seed: a new agent trained ``after`` episodes on the
  changed line (strategy **from scratch**), evaluated there;
- ``perturbed`` per algorithm and training seed: the transfer cell's agent of the same seed
  (trained again: the same episodes up to the change), shrunk and perturbed at the change
  (``shrink_perturb``) and trained ``after`` more (strategy **shrink-and-perturb**);
- ``cloned`` per algorithm and training seed: a new agent first cloned from the exact oracle's
  episodes on the changed line (``clone_oracle``), then trained ``after`` episodes there (strategy
  **new, cloned from the oracle**).

Evaluation: ``evaluations`` deterministic episodes from seed 10000 (held out: no training episode
starts from them), on the line after the change, through the node like the training; and the
same episodes on the line before the change (``BEFORE_EVALUATIONS``, the report's forgetting):
every trained agent, and the snapshot at the change.

Algorithms: MaskablePPO (sb3-contrib; it reads the env's action masks) and A2C (SB3). A2C rather
than DQN because it is on-policy like PPO: "continued" then means the same for both, learning from
fresh experience after the change, where DQN would go on replaying pre-change transitions from its
buffer with its exploration already decayed to its floor (its epsilon schedule runs over the whole
budget), which would measure the schedule as much as the transfer. A2C takes no masks: before the
machine upgrade a mode 1 or 2 it picks runs as mode 0 (the node refuses the mode and keeps mode 0,
as the library does), and its frozen snapshot is evaluated the same way.

Engines (``--engine``): ``sb3`` trains each cell with SB3 (``run_cell``); ``batched`` trains the
cells of one scenario, kind and algorithm that differ only by seed at once with the batched trainer
(``training/batched``, native lines; ``run_batch``), then evaluates each seed's SB3 model exactly as
``sb3`` does and gives each its own record, naming the engine.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..line.vocabulary import EPISODE_STEPS
from ..reports.benchmark_summary import HELDOUT_SEED
from . import transfer_warm as warm
from .cell_store import ConfigurationMismatch

#: The scenarios, each a ready schedule (evolutions/<name>.yaml): the paper's machine and sensor
#: upgrade, its sensor half and its machine half (both ending on advanced B as it does), the drift of
#: noise and threshold together, each alone, and the change of input and penalty from setup A to B.
SCENARIOS = ("upgrade", "drift", "sensor", "machine", "noise-drift", "threshold-drift", "setup-a-to-b")
#: The scenarios of the study's first version: the default of --scenarios, and the only ones a store
#: written then has in its key (``key_scenarios``).
FIRST_SCENARIOS = ("upgrade", "drift")
ALGOS = ("ppo", "a2c")
#: The cells' kinds: a scenario's rule-based baselines, then per algorithm and seed the agent
#: trained before and after the change (its continued and frozen strategies), the one trained
#: from scratch after it, and the one shrunk and perturbed at the change (reports/transfer_report.py's
#: STRATEGIES reads each strategy's record).
KINDS = ("baselines", "transfer", "scratch", "perturbed", "cloned")
#: A trained cell's evaluations on the line before the change (the report's forgetting), per kind:
#: a cell saved without them (before forgetting was measured) is trained again (``outdated``).
BEFORE_EVALUATIONS = {
    "transfer": ("continued_before_eval", "frozen_before_eval"),
    "scratch": ("scratch_before_eval",),
    "perturbed": ("perturbed_before_eval",),
    "cloned": ("cloned_before_eval",),
}
#: The strategy a trained cell's record keys are named after, per kind.
STRATEGY_OF = {"transfer": "continued", "scratch": "scratch", "perturbed": "perturbed", "cloned": "cloned"}
#: Episodes of the moving mean of the training curves; --before and --after are multiples of it.
WINDOW = 10
#: The held-out evaluation's first seed: the benchmark's (no training episode starts there).
EVAL_SEED = HELDOUT_SEED
#: MaskablePPO as the study ran it from the start (10-episode rollouts; SB3's defaults otherwise).
PPO_PARAMS = {"n_steps": 10 * EPISODE_STEPS, "batch_size": 100, "n_epochs": 5}
#: --ppo-settings: "study" is PPO_PARAMS; "paper" adds the paper's gamma, learning rate and entropy
#: coefficient (the benchmark's `hyperparams/ppo.yml`) on the same rollouts, which must stay whole
#: episodes dividing --before so that the frozen snapshot is taken exactly at the change.
PPO_SETTINGS = ("study", "paper")
#: Who trains the agents: SB3 cell by cell, or the batched trainer with a cell's seeds at once.
ENGINES = ("sb3", "batched")


@dataclass(frozen=True)
class Cell:
    """One saved unit of the study."""

    scenario: str
    kind: str
    algo: str | None = None
    seed: int | None = None

    @property
    def name(self) -> str:
        if self.kind == "baselines":
            return f"{self.scenario}_baselines"
        return f"{self.scenario}_{self.algo}_{self.kind}_seed{self.seed}"


def plan(scenarios, algos, seeds) -> list[Cell]:
    """Baselines first (seconds), then seed by seed every scenario and algorithm, so that a partial
    study has whole seeds."""
    cells = [Cell(s, "baselines") for s in scenarios]
    cells += [Cell(s, kind, a, seed) for seed in seeds for s in scenarios for a in algos for kind in KINDS[1:]]
    return cells


def hyperparameters(algo: str, ppo_settings: str = "study") -> dict[str, Any]:
    """The constructor arguments of ``algo`` in this study: PPO by ``ppo_settings`` (above), A2C the
    paper's (the benchmark's `hyperparams/a2c.yml`)."""
    from ..line.vocabulary import check
    from ..training import hyperparams

    check("algo", algo, ALGOS)
    paper = hyperparams.split(hyperparams.load(algo, "advanced"))[1]
    if algo != "ppo":
        return paper
    return dict(PPO_PARAMS) if ppo_settings == "study" else {**paper, **PPO_PARAMS}


def schedule_digest(scenario: str) -> str:
    from ..envs.evolving import schedule_file

    return hashlib.sha256(schedule_file(scenario).read_bytes()).hexdigest()[:16]


@dataclass(frozen=True)
class Settings:
    """The options that change a cell's result (the key of the saved cells)."""

    before: int
    after: int
    evaluations: int
    ppo_settings: str = "study"
    #: Where the lines run ("ros" or "native"); not in the key: both give the same cells.
    backend: str = "ros"

    def key(self, algos=ALGOS, scenarios=SCENARIOS) -> dict[str, Any]:
        # ppo_settings enters the key through the hyperparameters it gives, so that studies saved
        # before the option existed keep their key.
        fields = {k: v for k, v in asdict(self).items() if k not in ("ppo_settings", "backend")}
        return {
            **fields,
            "episode_steps": EPISODE_STEPS,
            "eval_seed": EVAL_SEED,
            "window": WINDOW,
            "hyperparameters": {a: hyperparameters(a, self.ppo_settings) for a in algos},
            "schedules": {s: schedule_digest(s) for s in scenarios},
        }


class OlderStore(ConfigurationMismatch):
    """A results directory written before some of the asked scenarios existed."""


def key_scenarios(saved_key: dict[str, Any] | None, asked, where: str = "the store") -> tuple[str, ...]:
    """The scenarios whose schedules are in the key of a store (``saved_key``: its study.json's key,
    None for a new one; ``where``: the store, for the message): ``SCENARIOS``, or ``FIRST_SCENARIOS``
    for a store of the first version, so that its cells stay valid; such a store refuses the other
    scenarios (``OlderStore``)."""
    if saved_key is None or set(saved_key.get("schedules", {})) != set(FIRST_SCENARIOS):
        return SCENARIOS
    newer = [s for s in asked if s not in FIRST_SCENARIOS]
    if newer:
        raise OlderStore(
            f"{where} was written before the scenarios {', '.join(newer)} existed (its key holds the schedules "
            f"of {', '.join(FIRST_SCENARIOS)} only): allowed there --scenarios {' '.join(FIRST_SCENARIOS)}; "
            "run the others into another --out"
        )
    return FIRST_SCENARIOS


def ready_events(scenario: str) -> list[dict[str, Any]]:
    """The events of the ready schedule of ``scenario`` (one of ``SCENARIOS``)."""
    from ..envs.evolving import schedule_file
    from ..line.vocabulary import check

    return yaml.safe_load(schedule_file(check("scenario", scenario, SCENARIOS)).read_text())["events"]


def start_line() -> dict[str, Any]:
    """The settings every line of the study starts from before its schedule: advanced B (``make_env``
    and ``library`` run setup B, and the evolving line has the advanced hardware), from the library."""
    from ..line.vocabulary import SETUPS, THRESHOLD

    return {**SETUPS["B"], "threshold": THRESHOLD, **VARIANT_HARDWARE["advanced"]}


#: The hardware of the paper's two variants, as the schedule's fields name it (src/sim/evolution.rs).
VARIANT_HARDWARE = {
    "basic": {"sort_modes": False, "ratio_sensor": False},
    "advanced": {"sort_modes": True, "ratio_sensor": True},
}


def line_states(scenario: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """The settings of the line of ``scenario`` before its change (episode 0's events) and after
    all of it (every event), as the schedule's fields name them."""
    before, after = start_line(), start_line()
    for e in ready_events(scenario):
        fields = {k: v for k, v in e.items() if k != "at"}
        if e["at"].get("episode") == 0:
            before.update(fields)
        after.update(fields)
    return before, after


def paper_line(state: dict[str, Any]) -> tuple[str, str] | None:
    """(setup, variant) of the paper whose line has the settings ``state``, or None: where rba and
    rba-hold, built for a setup, run on that setup itself."""
    from ..line.vocabulary import SETUPS, THRESHOLD

    for setup, settings in SETUPS.items():
        for variant, hardware in VARIANT_HARDWARE.items():
            if state == {**settings, "threshold": THRESHOLD, **hardware}:
                return setup, variant
    return None


def fixed_line(state: dict[str, Any]) -> dict[str, Any]:
    """The library's settings of the fixed line (no schedule) with the dynamics and rewards of the
    line with the settings ``state``: the variant of its machine (sort modes: advanced), its input,
    noise, penalty and threshold. The ratio sensor does not enter: it changes what an agent reads,
    not what a step does, and the oracle reads nothing. The oracle solves this line."""
    variant = next(v for v, hardware in VARIANT_HARDWARE.items() if hardware["sort_modes"] == state["sort_modes"])
    fields = ("input", "obs_noise", "action_penalty", "threshold")
    return {"variant": variant, **{k: state[k] for k in fields}, "max_steps": EPISODE_STEPS}


def frozen_mode0(scenario: str) -> bool:
    """Whether the line of ``scenario`` has no sort modes before its change: the frozen snapshot
    never chose one, and is evaluated on the changed line with the old machine's masks."""
    return not line_states(scenario)[0]["sort_modes"]


def schedules(scenario: str, before: int, out: Path) -> tuple[Path, Path]:
    """(the evolving schedule with the change after `before` episodes, the changed line's schedule
    from episode 0), written to `out`/schedules/, from the ready schedule of `scenario`."""
    events = ready_events(scenario)
    first = min(e["at"]["episode"] for e in events if e["at"].get("episode", 0) > 0)
    evolving, final = [], {}
    for e in events:
        e = dict(e)
        episode = e["at"]["episode"]
        if episode > 0:
            # The first change lands at before + 1; later ones keep their spacing, scaled to 1/20.
            e["at"] = {"episode": before + 1 + (episode - first) // 20}
        evolving.append(e)
        final.update({k: v for k, v in e.items() if k != "at"})
    a, b = schedule_paths(scenario, before, out)
    a.parent.mkdir(parents=True, exist_ok=True)
    a.write_text(yaml.safe_dump({"events": evolving}, sort_keys=False))
    b.write_text(yaml.safe_dump({"events": [{"at": {"episode": 0}, **final}]}, sort_keys=False))
    # The line before the change alone, for the baselines (random, and rba where it is no paper setup).
    initial = {k: v for e in events if e["at"].get("episode") == 0 for k, v in e.items() if k != "at"}
    first_line = {"events": [{"at": {"episode": 0}, **initial}]}
    before_path(scenario, out).write_text(yaml.safe_dump(first_line, sort_keys=False))
    return a, b


def make_env(schedule: Path, backend: str = "ros"):
    import gymnasium
    from stable_baselines3.common.monitor import Monitor

    import sorting_line_gym  # noqa: F401 - registers the ids

    env = gymnasium.make(
        "sorting_line_gym:SortingLineEvolving-v0",
        evolution=str(schedule),
        setup="B",
        max_episode_steps=EPISODE_STEPS,
        step_timeout=10.0,
        backend=backend,
    )
    return Monitor(env)


def algorithm_class(algo: str):
    from ..line.vocabulary import check

    if check("algo", algo, ALGOS) == "ppo":
        from sb3_contrib import MaskablePPO

        return MaskablePPO
    from stable_baselines3 import A2C

    return A2C


def new_model(algo: str, env, seed: int, settings: Settings):
    params = hyperparameters(algo, settings.ppo_settings)
    return algorithm_class(algo)("MlpPolicy", env, seed=seed, device="cpu", verbose=0, **params)


def act(model, algo: str, obs, masks: np.ndarray) -> int:
    """The deterministic action of ``model``; an A2C action the masks refuse runs in mode 0, as on the line."""
    if algo == "ppo":
        return int(model.predict(obs, action_masks=masks, deterministic=True)[0])
    from ..line.vocabulary import decode_action, encode_actions

    action = int(model.predict(obs, deterministic=True)[0])
    return action if masks[action] else encode_actions("advanced", decode_action("advanced", action)[0], 0)


def evaluate(model, algo: str, env, episodes: int, mode0: bool) -> list[float]:
    """Deterministic episodes of `model` on `env` (seeds 10000, 10001, ...); `mode0`: the masks of a
    machine without sort modes, whatever the line has."""
    from ..line.vocabulary import action_mask

    rewards = []
    for i in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + i)
        total, done = 0.0, False
        while not done:
            masks = env.get_wrapper_attr("action_masks")()
            if mode0:
                masks = action_mask("advanced", sort_modes=False)
            obs, reward, terminated, truncated, _ = env.step(act(model, algo, obs, masks))
            total += float(reward)
            done = terminated or truncated
        rewards.append(total)
    return rewards


def oracle_demonstrations(scenario: str, changed: Path):
    """``warm.oracle_demonstrations`` of the line after the change of ``scenario``: the oracle of
    that side's ``fixed_line``, replayed on the changed schedule's native line."""
    env = make_env(changed, "native")
    try:
        return warm.oracle_demonstrations(fixed_line(line_states(scenario)[1]), env)
    finally:
        env.close()


def evaluations(cell: Cell, settings: Settings, trained, at_change: Path | None, changed: Path, before: Path,
                backend: str) -> dict[str, list[float]]:  # fmt: skip
    """A trained cell's evaluation episodes: on the changed line the ``trained`` agent's and, for a
    transfer or perturbed cell, its snapshot ``at_change``'s (frozen; perturbed at the change), the
    snapshot with the old machine's masks where the old machine had no modes; on the line before
    the change (``before``) the trained agent's and the transfer cell's snapshot's
    (``BEFORE_EVALUATIONS``), with that line's own masks."""
    n, mode0 = settings.evaluations, frozen_mode0(cell.scenario)
    if cell.kind == "cloned":  # a new agent's snapshot: the changed line's masks
        mode0 = False
    strategy = STRATEGY_OF[cell.kind]
    snapshot = algorithm_class(cell.algo).load(at_change, device="cpu") if at_change is not None else None
    found: dict[str, list[float]] = {}
    env = make_env(changed, backend)
    try:
        if snapshot is not None:
            at = "frozen_eval" if cell.kind == "transfer" else f"{strategy}_at_change_eval"
            found[at] = evaluate(snapshot, cell.algo, env, n, mode0)
        found[f"{strategy}_eval"] = evaluate(trained, cell.algo, env, n, False)
    finally:
        env.close()
    env = make_env(before, backend)
    try:
        found[f"{strategy}_before_eval"] = evaluate(trained, cell.algo, env, n, False)
        if cell.kind == "transfer":
            found["frozen_before_eval"] = evaluate(snapshot, cell.algo, env, n, False)
    finally:
        env.close()
    return found


def run_transfer(cell: Cell, settings: Settings, out: Path) -> dict[str, Any]:
    """Strategies continued and frozen (a transfer cell): one agent through the change, and its
    snapshot at it; or shrink-and-perturb (a perturbed cell): the same agent, shrunk and perturbed
    at the change."""
    started = time.monotonic()
    evolving, changed = schedule_paths(cell.scenario, settings.before, out)
    models = out / "models"
    models.mkdir(parents=True, exist_ok=True)
    env = make_env(evolving, settings.backend)
    try:
        model = new_model(cell.algo, env, cell.seed, settings)
        model.learn(settings.before * EPISODE_STEPS)
        if cell.kind == "perturbed":
            warm.shrink_perturb(model, int(cell.seed))  # type: ignore[arg-type]
        snapshot = models / f"{cell.name}-at-the-change.zip"
        model.save(snapshot)
        model.learn(settings.after * EPISODE_STEPS, reset_num_timesteps=False)
        curve = [float(r) for r in env.get_episode_rewards()]
    finally:
        env.close()
    trained = time.monotonic()
    found = evaluations(cell, settings, model, snapshot, changed, before_path(cell.scenario, out), settings.backend)
    timing = {"train_seconds": trained - started, "eval_seconds": time.monotonic() - trained}
    curve_key = "continued_curve" if cell.kind == "transfer" else "perturbed_curve"
    return {curve_key: curve, **found, **timing}


def run_scratch(cell: Cell, settings: Settings, out: Path) -> dict[str, Any]:
    """Strategy from scratch (a scratch cell): a new agent on the changed line; or new, cloned from
    the oracle (a cloned cell): the same, cloned from the oracle's episodes before it trains."""
    started = time.monotonic()
    changed = schedule_paths(cell.scenario, settings.before, out)[1]
    env = make_env(changed, settings.backend)
    cloned: dict[str, Any] = {}
    try:
        model = new_model(cell.algo, env, cell.seed, settings)
        snapshot = None
        if cell.kind == "cloned":
            demonstrations = oracle_demonstrations(cell.scenario, changed)
            cloned["clone_losses"] = warm.clone_oracle(model, int(cell.seed), demonstrations)  # type: ignore[arg-type]
            snapshot = out / "models" / f"{cell.name}-cloned.zip"
            snapshot.parent.mkdir(parents=True, exist_ok=True)
            model.save(snapshot)
        model.learn(settings.after * EPISODE_STEPS)
        curve = [float(r) for r in env.get_episode_rewards()]
    finally:
        env.close()
    trained = time.monotonic()
    found = evaluations(cell, settings, model, snapshot, changed, before_path(cell.scenario, out), settings.backend)
    timing = {"train_seconds": trained - started, "eval_seconds": time.monotonic() - trained}
    return {f"{STRATEGY_OF[cell.kind]}_curve": curve, **cloned, **found, **timing}


def library(
    command: str, agent: str | None, variant: str, episodes: int, schedule: Path | None = None, setup: str = "B"
) -> list[float]:
    """Per-episode rewards of `sorting_line eval` (an agent) or `sorting_line oracle` on ``setup``
    (the study's B by default) and ``variant``, on ``schedule`` if given (eval only), seeds
    10000..., offline (``rewards``)."""
    from ..line.vocabulary import SETUPS, THRESHOLD, check_setup, check_variant

    settings = dict(SETUPS[check_setup(setup)], variant=check_variant(variant), threshold=THRESHOLD)
    settings["max_steps"] = EPISODE_STEPS
    if schedule is not None:
        settings["evolution"] = str(schedule)
    return rewards(command, agent, settings, episodes)


#: The library's two offline evaluations: an agent's (``_native.evaluate``) and the oracle's.
COMMANDS = ("eval", "oracle")


def rewards(command: str, agent: str | None, settings: dict[str, Any], episodes: int) -> list[float]:
    """Per-episode rewards of `sorting_line eval` (``agent``) or `sorting_line oracle` on the line of
    the library's ``settings``, seeds 10000..., offline: the library's own evaluation, in this
    process (``_native.evaluate`` and ``_native.oracle_eval`` give the JSON of the two commands)."""
    import sorting_line_gym._native as _native

    from ..line.vocabulary import check

    if check("command", command, COMMANDS) == "oracle":
        if "evolution" in settings:
            raise ValueError("the oracle models a fixed line; it cannot solve an evolving one")
        summary = _native.oracle_eval(settings, episodes, EVAL_SEED)
    else:
        summary = _native.evaluate(agent, settings, episodes, EVAL_SEED)
    return [float(e["reward"]) for e in summary["per_episode"]]


def run_baselines(cell: Cell, settings: Settings, changed: Path, before: Path) -> dict[str, Any]:
    """rba, rba-hold and random before and after the change, and the oracle of each side.

    rba and rba-hold, built for a setup, run on the line before the change as that setup where it is
    one of the paper's (``paper_line``: the agents weigh the readings by the noise of the setup they
    are built for), else on ``before`` (the schedule of that line); after the change on the changed
    schedule, as the agents trained there. random runs on the schedules of both sides. The oracle
    takes no schedule: it solves each side's ``fixed_line``, once random's episodes there equal its
    episodes on the side's schedule to the last digit (the oracle depends on the line's dynamics and
    rewards, which random's actions see, not on what it reads); otherwise the record says why it is
    missing (``oracle_before_missing``, ``oracle_after_missing``)."""
    n = settings.evaluations
    states = dict(zip(("before", "after"), line_states(cell.scenario), strict=True))
    on_schedule = {"before": before, "after": changed}
    record: dict[str, Any] = {"before": {}, "after": {}}
    first = paper_line(states["before"])
    for agent in ("rba", "rba-hold"):
        if first is not None:
            record["before"][agent] = library("eval", agent, first[1], n, setup=first[0])
        else:
            record["before"][agent] = library("eval", agent, "advanced", n, before)
        record["after"][agent] = library("eval", agent, "advanced", n, changed)
    for side, schedule in on_schedule.items():
        record[side]["random"] = library("eval", "random", "advanced", n, schedule)
        line = fixed_line(states[side])
        if rewards("eval", "random", line, n) == record[side]["random"]:
            record[side]["oracle"] = rewards("oracle", None, line, n)
        else:
            record[f"oracle_{side}_missing"] = (
                f"random's episodes on the fixed line {line} differ from those on the schedule {schedule.name}: "
                "the oracle of that line is not this one's"
            )
    return record


def outdated(record: dict[str, Any]) -> str | None:
    """Why the study runs a saved cell again, or None: a baselines cell of the study's first
    version recorded no random agent (the lower reference of the normalised curves) and the oracle
    on the paper's setups only; it is redone offline in seconds. A trained cell saved before
    forgetting was measured has no evaluations on the line before the change
    (``BEFORE_EVALUATIONS``), and its final agent was not kept: it is trained again."""
    kind = record["cell"]["kind"]
    if kind == "baselines" and any("random" not in record[side] for side in ("before", "after")):
        return "a baselines cell of the study's first version (no random agent's episodes): run again, offline"
    missing = [k for k in BEFORE_EVALUATIONS.get(kind, ()) if k not in record]
    if missing:
        return (
            f"a {kind} cell without evaluations on the line before the change ({', '.join(missing)}: "
            "forgetting), saved before they were made: trained again"
        )
    return None


def run_cell(cell: Cell, settings: Settings, out: Path) -> dict[str, Any]:
    """Runs one cell (in this process); returns its record (saved by the caller)."""
    import torch

    torch.set_num_threads(1)  # small MLPs on 2 cores: the other core for the node and the bridge
    started = time.monotonic()
    changed = schedule_paths(cell.scenario, settings.before, out)[1]
    if cell.kind == "baselines":
        result = run_baselines(cell, settings, changed, before_path(cell.scenario, out))
    elif cell.kind in ("transfer", "perturbed"):
        result = run_transfer(cell, settings, out)
    else:
        result = run_scratch(cell, settings, out)
    return {"cell": asdict(cell), **result, "seconds": time.monotonic() - started}


def schedule_paths(scenario: str, before: int, out: Path) -> tuple[Path, Path]:
    """Where ``schedules`` wrote the scenario's two schedules (the study writes them at its start)."""
    return out / "schedules" / f"{scenario}-at-{before + 1}.yaml", out / "schedules" / f"{scenario}-after.yaml"


def before_path(scenario: str, out: Path) -> Path:
    """Where ``schedules`` wrote the schedule of the scenario's line before the change."""
    return out / "schedules" / f"{scenario}-before.yaml"


# ------------------------------------------------------------------------------------------
# --engine batched


def batches(todo: list[Cell]) -> list[list[Cell]]:
    """The cells as ``--engine batched`` runs them: baselines alone, the cells of one scenario, kind
    and algorithm together (their seeds differ), in the order of each group's first cell."""
    groups: dict[Any, list[Cell]] = {}
    for c in todo:
        groups.setdefault(c if c.kind == "baselines" else (c.scenario, c.kind, c.algo), []).append(c)
    return list(groups.values())


class Curves:
    """Every finished training episode's return per seed, as ``Monitor.get_episode_rewards`` gives
    them (summed in float32 by the lines, as VecMonitor does: Monitor's sums differ in the 7th
    digit), read from the trainer's lines after each update."""

    def __init__(self, n_seeds: int):
        self.curves: list[list[float]] = [[] for _ in range(n_seeds)]
        self.seen = [0] * n_seeds

    def __call__(self, trainer) -> None:
        lines = trainer.lines
        for s, count in enumerate(int(c) for c in lines.episode_counts):
            new = count - self.seen[s]
            if new > len(lines.episodes[s]):  # more episodes in one update than its statistics window holds
                raise RuntimeError(
                    f"{new} episodes in one update: the curve would miss some (window {len(lines.episodes[s])})"
                )
            self.curves[s] += [float(e["r"]) for e in list(lines.episodes[s])[len(lines.episodes[s]) - new :]]
            self.seen[s] = count


def _trainer(cell: Cell, seeds: list[int], settings: Settings, schedule: Path):
    from ..training.batched.on_policy import OnPolicyTrainer

    return OnPolicyTrainer(
        "maskable_ppo" if cell.algo == "ppo" else cell.algo,  # the study's PPO is MaskablePPO
        seeds,
        setup="B",
        variant="advanced",
        params=hyperparameters(cell.algo, settings.ppo_settings),
        lines_per_seed=1,
        episode_steps=EPISODE_STEPS,
        evolution=str(schedule),
    )


def _learn(trainer, steps: int, curves: Curves, progress: bool, reset: bool = True) -> None:
    """``trainer.learn``, with the training command's bar (a seed's steps, the steps/s of all) if ``progress``."""
    from ..training.train_batched import progress_bar

    bar, update = progress_bar(steps, len(trainer.seeds)) if progress else (None, None)
    start = trainer.num_timesteps if not reset else 0

    def each(t) -> None:
        curves(t)
        if update is not None:
            update(_Offset(t, start))

    try:
        trainer.learn(steps, each, reset_num_timesteps=reset)
    finally:
        if bar is not None:
            bar.close()


class _Offset:
    """A trainer seen by the progress bar as if its steps counted from ``start`` (a continued learn)."""

    def __init__(self, trainer, start: int):
        self.num_timesteps = trainer.num_timesteps - start


def run_batch(
    cells: list[Cell], settings: Settings, out: Path, progress: bool = False, finished=None
) -> list[dict[str, Any]]:
    """Trains the ``cells`` (one scenario, kind and algorithm; their seeds differ) at once with the
    batched trainer on native lines, then evaluates each seed as ``run_cell`` does; returns their
    records (``finished(cell, record)`` as each is evaluated, so a cut batch keeps those). A
    record's ``train_seconds`` is its share of the batch's training."""
    import torch

    first = cells[0]
    if first.kind == "baselines" or any((c.scenario, c.kind, c.algo) != (first.scenario, first.kind, first.algo)
                                        for c in cells):  # fmt: skip
        raise ValueError(f"cells {[c.name for c in cells]}: allowed trained cells that differ only by seed")
    torch.set_num_threads(1)
    started = time.monotonic()
    evolving, changed = schedule_paths(first.scenario, settings.before, out)
    seeds = [int(c.seed) for c in cells]  # type: ignore[arg-type]
    curves = Curves(len(cells))
    snapshots: list[Path] = []
    clone_losses: list[list[float]] = []
    through = first.kind in ("transfer", "perturbed")  # trained through the change
    trainer = _trainer(first, seeds, settings, evolving if through else changed)
    try:
        if through:
            _learn(trainer, settings.before * EPISODE_STEPS, curves, progress)
            if first.kind == "perturbed":
                warm.in_batched(trainer, warm.shrink_perturb)
            models = out / "models"
            models.mkdir(parents=True, exist_ok=True)
            snapshots = trainer.save([models / f"{c.name}-at-the-change.zip" for c in cells])
            _learn(trainer, settings.after * EPISODE_STEPS, curves, progress, reset=False)
        else:
            if first.kind == "cloned":
                demonstrations = oracle_demonstrations(first.scenario, changed)
                clone_losses = warm.in_batched(trainer, lambda m, seed: warm.clone_oracle(m, seed, demonstrations))
                (out / "models").mkdir(parents=True, exist_ok=True)
                snapshots = trainer.save([out / "models" / f"{c.name}-cloned.zip" for c in cells])
            _learn(trainer, settings.after * EPISODE_STEPS, curves, progress)
        rate = trainer.num_timesteps * len(cells) / max(time.monotonic() - started, 1e-9)
        trained = trainer.sync_models()  # each seed's SB3 model with its trained weights
    finally:
        trainer.close()
    share = (time.monotonic() - started) / len(cells)
    batch = {"seeds": seeds, "steps_per_s": rate}
    records = []
    for s, cell in enumerate(cells):
        evaluated = time.monotonic()
        at_change = snapshots[s] if snapshots else None
        found = evaluations(cell, settings, trained[s], at_change, changed, before_path(cell.scenario, out), "native")
        result = {f"{STRATEGY_OF[cell.kind]}_curve": curves.curves[s], **found}
        if clone_losses:
            result["clone_losses"] = clone_losses[s]
        own = time.monotonic() - evaluated
        timing = {"train_seconds": share, "eval_seconds": own}
        record = {"cell": asdict(cell), **result, **timing, "seconds": share + own, "engine": "batched", "batch": batch}
        records.append(record)
        if finished is not None:
            finished(cell, record)
    return records
