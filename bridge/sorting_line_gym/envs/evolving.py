"""The evolving sorting line as a Gymnasium environment (`SortingLineEvolving-v0`): one line of a
`sorting_line node --evolution FILE`, whose setup changes during the run by an evolution schedule
(the paper's "evolving industrial environments": more sensor noise, a new quality threshold, the
machine upgrade that adds sort modes, the sensor upgrade that adds the ratio reading, faults).

## Description
The sorting line of `SortingLine-v0` / `SortingLineAdvanced-v0` (see their docstring), with the
schedule applied by the node: the schedule, the seeds and the actions fix the trajectory, which is
`sorting_line trace --evolution FILE` for the same seeds and actions.

## Action space
`Discrete(30)` throughout, `speed_index * 3 + mode` (mode 0 basic, 1 positive (A-rich), 2 negative (B-rich)), whatever
the hardware. Before the machine upgrade (`sort_modes` off) only mode 0 is valid:
`action_masks()` allows the ten actions with mode 0 (sb3-contrib's MaskablePPO reads it). A
masked action is still sent as it is: the node refuses its mode (counted as
`rejected_sort_modes_off` on /diagnostics) and the step runs in mode 0, as the library does.

## Observation space
`Box(0, 2, (2,), float32)` throughout: the input sensor's reading and the ratio category (0, 1,
2). Before the sensor upgrade (`ratio_sensor` off) the category is unknown and reads **0.5**
(`vocabulary.CATEGORY_UNKNOWN_OBSERVATION`): inside the box, and no category's value, so a policy
can tell "no sensor" from "mixed batch" and keeps its input layer across the upgrade.

## Reward
As the fixed lines', with the threshold and switching penalty the schedule has set.

## Episodes and the schedule
The schedule's episode E starts at the line's E-th reset: with `node="spawn"` (the default) this
env's E-th `reset()`. Its tick T is the line's T-th step since the node started, across episodes.
The line's episode 0 is the node's start-up state, before the first `reset()`. The first reset
is never repeated to the node (a slow reply is waited out; a lost first exchange means a fresh
node): `workarounds.late_matching`.

## Info
The fixed lines' keys, plus `evolution`: the events announced since the last step or reset (each
`{"at_reset", "episode", "tick", "changed": {field: value}}`; a tick's events are announced when
the line arrives at that tick, before the step they apply to), `settings` (the setup the next step
runs with: obs_noise, action_penalty, threshold, input, sort_modes, ratio_sensor) and
`line_tick`.

## Arguments
`evolution` and the line options it leaves to the user (`line/options.py`: the schedule sets the
rest), listed with their defaults and meanings at the end of the class docstring
(`help(SortingLineEvolvingEnv)`): the ready schedules are in `sorting_line_gym/evolutions/` (the
paper's upgrade after 2000 episodes; noise and threshold drift); `setup` is the line before the
schedule changes it; `node` is "spawn" or "attach" (with `namespace`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

from ..line.topics import EVOLUTION_EVENT
from ..line.vocabulary import action_mask, decode_action, line_infos, observations, sim_seconds, state_info
from .env import SEED_BOUND, action_space, observation_space
from .keywords import Keywords

#: The ready schedules, by name.
EVOLUTIONS_DIR = Path(__file__).resolve().parent.parent / "evolutions"
READY_SCHEDULES = tuple(sorted(p.stem for p in EVOLUTIONS_DIR.glob("*.yaml")))

#: The settings an EvolutionEvent carries, and how a changed value's text reads.
_SETTINGS = {
    "obs_noise": float,
    "action_penalty": float,
    "threshold": float,
    "input": str,
    "sort_modes": lambda v: v == "true",
    "ratio_sensor": lambda v: v == "true",
}


def schedule_file(evolution: str | Path) -> Path:
    """The schedule file of ``evolution``: a ready schedule's name or a path."""
    if str(evolution) in READY_SCHEDULES:
        return EVOLUTIONS_DIR / f"{evolution}.yaml"
    path = Path(evolution)
    if not path.is_file():
        raise ValueError(
            f"evolution = {str(evolution)!r} is not a schedule file: allowed a YAML file or one of "
            f"{', '.join(READY_SCHEDULES)}"
        )
    return path.resolve()


def tick_points(path: Path) -> frozenset[int]:
    """The ticks at which the schedule has events: where the env waits for their announcement.
    Only the points are read here; the node validates the schedule and refuses a bad one at start
    (its message names the event, the field, the value and the range)."""
    try:
        doc = yaml.safe_load(path.read_text()) or {}
        events = doc.get("events") or []
        return frozenset(int(e["at"]["tick"]) for e in events if isinstance(e, dict) and "tick" in (e.get("at") or {}))
    except (yaml.YAMLError, AttributeError, TypeError, ValueError):
        return frozenset()


def settings_of(message) -> dict:
    """The full setup an EvolutionEvent reports."""
    return {name: getattr(message, name) for name in _SETTINGS}


def announces_setup_of(episode: int):
    """Whether an EvolutionEvent is the announcement, at its reset, of episode ``episode``'s setup."""
    return lambda m: bool(m.at_reset) and m.episode == episode


def event_info(message) -> dict:
    return {
        "at_reset": bool(message.at_reset),
        "episode": int(message.episode),
        "tick": int(message.tick),
        "changed": dict(zip(message.changed, message.values, strict=False)),
    }


#: The keywords of SortingLineEvolvingEnv (and SortingLineEvolving-v0): the schedule sets the line's
#: variant and settings; the setup it starts from is B.
KEYWORDS = Keywords(exclude=("variant", "input", "obs_noise", "action_penalty", "threshold", "evolution"), setup="B")


@KEYWORDS
class SortingLineEvolvingEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": []}

    def __init__(self, evolution: str | Path = "upgrade", **keywords: Any):
        self.schedule = schedule_file(evolution)
        options = KEYWORDS.line_options(keywords, variant="advanced", evolution=str(self.schedule))
        if options.node not in ("spawn", "attach"):
            raise ValueError(
                f"node = {options.node!r} is not valid for the evolving line: allowed 'spawn' or 'attach' "
                "(a shared line server's lines do not evolve)"
            )
        self.observation_space = observation_space("advanced")
        self.action_space = action_space("advanced")
        self._ticks = tick_points(self.schedule)
        # rclpy loads with the env, not the module (the native backend's evolving line reads schedule_file).
        from sorting_line_interfaces.msg import EvolutionEvent

        from ..ros.bank import LineBank

        self._inbox: list = []
        # One line through the batch topics, which are there whatever the hardware (cmd/sort_mode
        # comes and goes with the machine upgrade); events/evolution is watched beside them. A
        # first reset whose exchange was lost (its reply, step-0 state or setup announcement) goes
        # to a fresh node (its events replace the old's).
        self.bank = LineBank(
            options,
            lines=1,
            batch=True,
            watch={EVOLUTION_EVENT: (EvolutionEvent, self._inbox.append)},
            on_fresh_node=self._inbox.clear,
            first_proof=self._setup_not_announced,
        )
        self._settings: dict | None = None
        self._line_tick: int | None = None
        self._announced: list = []

    @property
    def namespace(self) -> str:
        return self.bank.namespace

    @property
    def settings(self) -> dict:
        """The setup the next step runs with (after the events announced for it)."""
        if self._settings is None:
            raise RuntimeError("settings are known after the first reset()")
        return dict(self._settings)

    def action_masks(self) -> np.ndarray:
        """Valid actions now: all 30 with sort modes, the ten with mode 0 before the machine upgrade."""
        return action_mask("advanced", sort_modes=self._settings is not None and self._settings["sort_modes"])

    # -- the events ----------------------------------------------------------------------------
    def _setup_not_announced(self, results) -> str | None:
        """What the first reset's exchange still lacks on events/evolution: the setup of the
        episode it started (a node that has not matched our reader yet publishes it to nobody)."""
        episode = results[0].episode
        if any(map(announces_setup_of(episode), self._inbox)):
            return None
        return f"{EVOLUTION_EVENT}: the setup of episode {episode}"

    def _take(self, match, what: str):
        waiter = self.bank.waiter
        found = []

        def arrived() -> bool:
            hits = [m for m in self._inbox if match(m)]
            if hits:
                found.append(hits[-1])
            return bool(hits)

        waiter.until(arrived, self.bank.step_timeout, lambda: f"{self.namespace}/{EVOLUTION_EVENT}: {what}")
        message = found[-1]
        self._inbox[:] = [m for m in self._inbox if not match(m)]
        return message

    def _apply(self, message) -> None:
        for field, value in zip(message.changed, message.values, strict=False):
            if field in _SETTINGS:
                self._settings[field] = _SETTINGS[field](value)
        self._announced.append(event_info(message))

    def _pending_tick_events(self) -> None:
        """Waits for the announcement of the events due at the step the line now waits at, if the
        schedule has any there."""
        tick = self._line_tick
        if tick in self._ticks:
            self._apply(self._take(lambda m: not m.at_reset and m.tick == tick, f"the events due at tick {tick}"))

    # -- Gymnasium -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        node_seed = int(seed) if seed is not None else int(self.np_random.integers(0, SEED_BOUND))
        result = self.bank.reset({0: node_seed})[0]
        self._episode_start = sim_seconds(result.stamp.sec, result.stamp.nanosec)
        episode = result.episode
        message = self._take(announces_setup_of(episode), f"the setup of episode {episode}")
        self._settings = settings_of(message)
        self._line_tick = int(message.tick)
        self._announced = [event_info(message)] if len(message.event_indices) else []
        self._pending_tick_events()
        info = {"seed": int(result.seed), "step": 0, **self._evolution_info()}
        return observations("advanced", result.quantity, result.category), info

    def _evolution_info(self) -> dict:
        announced, self._announced = self._announced, []
        return {"evolution": announced, "settings": dict(self._settings), "line_tick": self._line_tick}

    def step(self, action):
        if not self.action_space.contains(action):
            raise ValueError(f"action {action!r} is not in {self.action_space}")
        speed_index, mode = decode_action("advanced", action)
        b = self.bank.step_batch(np.array([speed_index]), np.array([mode]))
        self._line_tick += 1
        self._pending_tick_events()
        obs = observations("advanced", b.observation_quantity[0], b.observation_category[0])
        info = line_infos(state_info(b, sim_seconds(b.stamp_sec, b.stamp_nanosec) - self._episode_start))[0]
        info.update(self._evolution_info())
        return obs, float(b.reward[0]), False, bool(b.truncated[0]), info

    def close(self):
        bank = getattr(self, "bank", None)
        if bank is not None:
            bank.close()
        super().close()
