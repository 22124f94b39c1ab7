"""The cells of the transfer study (`sorting-line-transfer`): what each one trains and evaluates.

A cell is saved as soon as it finishes (``studies.cell_store``), so a stopped study resumes cell
by cell. The cells of a scenario:

- ``baselines``: `rba` and `rba-hold` on the line before and after the change, and the oracle
  (`sorting_line oracle`, the clairvoyant optimum per seed) where the line is one it can solve;
- ``transfer`` per algorithm and training seed: one agent trained ``before`` episodes on the
  evolving line and ``after`` more past the change (strategy **continued**), and its snapshot at
  the change (strategy **frozen**), both evaluated on the changed line;
- ``scratch`` per algorithm and training seed: a new agent trained ``after`` episodes on the
  changed line (strategy **from scratch**), evaluated there.

Evaluation: ``evaluations`` deterministic episodes from seed 10000 (held out: no training episode
starts from them), on the line after the change, through the node like the training.

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

SCENARIOS = ("upgrade", "drift")
ALGOS = ("ppo", "a2c")
#: The cells' kinds: a scenario's rule-based baselines, then per algorithm and seed the agent
#: trained before and after the change (its continued and frozen strategies) and the one trained
#: from scratch after it (reports/transfer_report.py's EVALUATIONS reads each strategy's record).
KINDS = ("baselines", "transfer", "scratch")
#: Episodes of the moving mean of the training curves; --before and --after are multiples of it.
WINDOW = 10
EVAL_SEED = 10_000
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
    from ..training import hyperparams

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


def schedules(scenario: str, before: int, out: Path) -> tuple[Path, Path]:
    """(the evolving schedule with the change after `before` episodes, the changed line's schedule
    from episode 0), written to `out`/schedules/, from the ready schedule of `scenario`."""
    from ..envs.evolving import schedule_file

    events = yaml.safe_load(schedule_file(scenario).read_text())["events"]
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
    if algo == "ppo":
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
    action = int(model.predict(obs, deterministic=True)[0])
    return action if masks[action] else action - action % 3


def evaluate(model, algo: str, env, episodes: int, mode0: bool) -> list[float]:
    """Deterministic episodes of `model` on `env` (seeds 10000, 10001, ...); `mode0`: the masks of a
    machine without sort modes, whatever the line has."""
    rewards = []
    for i in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + i)
        total, done = 0.0, False
        while not done:
            masks = env.get_wrapper_attr("action_masks")()
            if mode0:
                masks = np.array([a % 3 == 0 for a in range(len(masks))])
            obs, reward, terminated, truncated, _ = env.step(act(model, algo, obs, masks))
            total += float(reward)
            done = terminated or truncated
        rewards.append(total)
    return rewards


def run_transfer(cell: Cell, settings: Settings, evolving: Path, changed: Path, models: Path) -> dict[str, Any]:
    """Strategies continued and frozen: one agent through the change, and its snapshot at it."""
    started = time.monotonic()
    env = make_env(evolving, settings.backend)
    try:
        model = new_model(cell.algo, env, cell.seed, settings)
        model.learn(settings.before * EPISODE_STEPS)
        snapshot = models / f"{cell.name}-at-the-change.zip"
        model.save(snapshot)
        model.learn(settings.after * EPISODE_STEPS, reset_num_timesteps=False)
        curve = [float(r) for r in env.get_episode_rewards()]
    finally:
        env.close()
    trained = time.monotonic()
    frozen_model = algorithm_class(cell.algo).load(snapshot, device="cpu")
    eval_env = make_env(changed, settings.backend)
    try:
        frozen = evaluate(frozen_model, cell.algo, eval_env, settings.evaluations, cell.scenario == "upgrade")
        continued = evaluate(model, cell.algo, eval_env, settings.evaluations, False)
    finally:
        eval_env.close()
    timing = {"train_seconds": trained - started, "eval_seconds": time.monotonic() - trained}
    return {"continued_curve": curve, "continued_eval": continued, "frozen_eval": frozen, **timing}


def run_scratch(cell: Cell, settings: Settings, changed: Path) -> dict[str, Any]:
    """Strategy from scratch: a new agent on the changed line."""
    started = time.monotonic()
    env = make_env(changed, settings.backend)
    try:
        model = new_model(cell.algo, env, cell.seed, settings)
        model.learn(settings.after * EPISODE_STEPS)
        curve = [float(r) for r in env.get_episode_rewards()]
    finally:
        env.close()
    trained = time.monotonic()
    eval_env = make_env(changed, settings.backend)
    try:
        final = evaluate(model, cell.algo, eval_env, settings.evaluations, False)
    finally:
        eval_env.close()
    timing = {"train_seconds": trained - started, "eval_seconds": time.monotonic() - trained}
    return {"scratch_curve": curve, "scratch_eval": final, **timing}


def library(command: str, agent: str | None, variant: str, episodes: int, schedule: Path | None = None) -> list[float]:
    """Per-episode rewards of `sorting_line eval` (an agent) or `sorting_line oracle` on setup B,
    seeds 10000..., offline: the library's own evaluation, in this process (``_native.evaluate``
    and ``_native.oracle_eval`` give the JSON of the two commands)."""
    import sorting_line_gym._native as _native

    from ..line.vocabulary import SETUPS, THRESHOLD

    settings = dict(SETUPS["B"], variant=variant, threshold=THRESHOLD, max_steps=EPISODE_STEPS)
    if command == "oracle":
        if schedule is not None:
            raise ValueError("the oracle models a fixed line; it cannot solve an evolving one")
        summary = _native.oracle_eval(settings, episodes, EVAL_SEED)
    else:
        if schedule is not None:
            settings["evolution"] = str(schedule)
        summary = _native.evaluate(agent, settings, episodes, EVAL_SEED)
    return [float(e["reward"]) for e in summary["per_episode"]]


def run_baselines(cell: Cell, settings: Settings, changed: Path) -> dict[str, Any]:
    """rba and rba-hold before and after the change; the oracle of each side where the oracle can
    solve it. It models the paper's fixed lines, so after the change it is used only when the
    changed line is advanced B (rba-hold's episodes there equal the schedule's to the last digit);
    otherwise the record says why it is missing."""
    n = settings.evaluations
    before_variant = "basic" if cell.scenario == "upgrade" else "advanced"
    record: dict[str, Any] = {"before": {}, "after": {}}
    for agent in ("rba", "rba-hold"):
        record["before"][agent] = library("eval", agent, before_variant, n)
        record["after"][agent] = library("eval", agent, "advanced", n, changed)
    record["before"]["oracle"] = library("oracle", None, before_variant, n)
    if library("eval", "rba-hold", "advanced", n) == record["after"]["rba-hold"]:
        record["after"]["oracle"] = library("oracle", None, "advanced", n)
    else:
        record["oracle_after_missing"] = (
            "the changed line is not one of the paper's setups (the oracle models those: it takes no schedule)"
        )
    return record


def run_cell(cell: Cell, settings: Settings, out: Path) -> dict[str, Any]:
    """Runs one cell (in this process); returns its record (saved by the caller)."""
    import torch

    torch.set_num_threads(1)  # small MLPs on 2 cores: the other core for the node and the bridge
    started = time.monotonic()
    evolving, changed = schedule_paths(cell.scenario, settings.before, out)
    if cell.kind == "baselines":
        result = run_baselines(cell, settings, changed)
    elif cell.kind == "transfer":
        models = out / "models"
        models.mkdir(parents=True, exist_ok=True)
        result = run_transfer(cell, settings, evolving, changed, models)
    else:
        result = run_scratch(cell, settings, changed)
    return {"cell": asdict(cell), **result, "seconds": time.monotonic() - started}


def schedule_paths(scenario: str, before: int, out: Path) -> tuple[Path, Path]:
    """Where ``schedules`` wrote the scenario's two schedules (the study writes them at its start)."""
    return out / "schedules" / f"{scenario}-at-{before + 1}.yaml", out / "schedules" / f"{scenario}-after.yaml"


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
    trainer = _trainer(first, seeds, settings, evolving if first.kind == "transfer" else changed)
    try:
        if first.kind == "transfer":
            _learn(trainer, settings.before * EPISODE_STEPS, curves, progress)
            models = out / "models"
            models.mkdir(parents=True, exist_ok=True)
            snapshots = trainer.save([models / f"{c.name}-at-the-change.zip" for c in cells])
            _learn(trainer, settings.after * EPISODE_STEPS, curves, progress, reset=False)
        else:
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
        eval_env = make_env(changed, "native")
        try:
            if cell.kind == "transfer":
                frozen_model = algorithm_class(cell.algo).load(snapshots[s], device="cpu")
                frozen = evaluate(frozen_model, cell.algo, eval_env, settings.evaluations, cell.scenario == "upgrade")
                continued = evaluate(trained[s], cell.algo, eval_env, settings.evaluations, False)
                result = {"continued_curve": curves.curves[s], "continued_eval": continued, "frozen_eval": frozen}
            else:
                final = evaluate(trained[s], cell.algo, eval_env, settings.evaluations, False)
                result = {"scratch_curve": curves.curves[s], "scratch_eval": final}
        finally:
            eval_env.close()
        own = time.monotonic() - evaluated
        timing = {"train_seconds": share, "eval_seconds": own}
        record = {"cell": asdict(cell), **result, **timing, "seconds": share + own, "engine": "batched", "batch": batch}
        records.append(record)
        if finished is not None:
            finished(cell, record)
    return records
