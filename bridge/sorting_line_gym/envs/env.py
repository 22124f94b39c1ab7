"""The sorting line as a Gymnasium environment, one line of a `sorting_line` ROS 2 node.

## Description
Material enters a conveyor belt in batches of two materials, A and B; a sorting machine splits
each batch into two containers. The faster the belt, the more it earns, but the less accurately a
crowded belt is sorted. The advanced line adds a ratio sensor and a sorting mode that helps when it
matches the batch (positive for an A-rich batch, negative for a B-rich one, basic for a mixed one).
This is the SortingEnv benchmark (Maus et al.) with the reference implementation's dynamics,
simulated by the Rust node and reached over ROS 2 topics.

## Action space
- `SortingLine-v0`: `Discrete(10)`, the belt speed index i (speed (i + 1) / 10).
- `SortingLineAdvanced-v0`: `Discrete(30)`, `speed_index * 3 + mode`, mode 0 basic, 1 positive (A-rich),
  2 negative (B-rich) (the library's names, `line.vocabulary.MODES`).

## Observation space
- basic: `Box(0, 1, (1,), float32)`: the input sensor's reading of the next batch's amount
  (relative noise in setups C, D; two decimals).
- advanced: `Box(0, 2, (2,), float32)`: the reading and the next batch's ratio category (0, 1, 2).
The action answers the observation: it sets the speed (and mode) the observed batch is sorted at.

## Reward
If the accuracy of the batch is below the threshold (0.7): -0.1. Otherwise
0.5 * (accuracy - 0.7) / 0.3 + 0.5 * (speed - 0.1) / 0.9 - penalty, where the penalty (0.5 in
setups B, D) is charged when the belt speed changes.

## Connecting
Constructing the env starts nothing: the node process (or lease) and rclpy come at the first
`reset()`, so a dummy env made only to read the spaces (Gymnasium's AsyncVectorEnv does this in
its parent before it forks) costs nothing. rclpy is not fork-safe: an env used in a process
forked after rclpy went live there raises `BridgeError` saying so, instead of blocking.

## Starting state
Fixed line contents (input 30/50, belt 40/20, machine 75/25, speed 0.6); `reset(seed=s)` restarts
the node's random streams from s, so the same seed and actions give the same trajectory as
`sorting_line trace --seed s` and `sorting_line eval`.

## Episode end
No terminal state. Episodes are truncated by the time limit: `gymnasium.make` applies a TimeLimit
of 50 steps (`max_episode_steps=250` for training); constructing the class directly with
`max_episode_steps=N` makes the node truncate at N.

## Arguments
The line options (`line/options.py`) as keyword arguments, and `render_mode`: listed with their
defaults and meanings at the end of the class docstring (`help(SortingLineEnv)`). `node="shared"`
leases a line of this host's line server, `line_server`, started when none has a free line and
stopped 8 s after its last env (64 envs start in seconds); a wait that outlasts `step_timeout`
fails naming the namespace, topic and tick; `input`, `obs_noise`, `action_penalty` and `threshold`
are the node's options of the same name, with their ranges.

## Info
accuracy, purity (correct / all sorted), recall_a, recall_b, speed, speed_index, mode, occupancy,
containers (a, a_false, b, b_false), speed_changes, cumulative_reward, step, sim_time (simulated
seconds since the reset), seed.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..line.vocabulary import (
    ACTION_COUNTS,
    CATEGORIES,
    ENV_IDS,
    EPISODE_STEPS,
    START_ACCURACY,
    START_CONTENTS,
    START_OCCUPANCY,
    START_SPEED,
    action_mask,
    check_variant,
    decode_action,
    observations,
    sim_seconds,
    state_info,
)
from .keywords import Keywords

#: Largest seed the bridge draws for the node when reset() gets none.
SEED_BOUND = 2**63


def observation_space(variant: str) -> spaces.Box:
    """The reading (0..1); on the advanced line, then the ratio category. One bound for both, the
    highest category (2), as the reference implementation's space has it (saved models check it)."""
    if variant == "advanced":
        return spaces.Box(low=0.0, high=float(max(CATEGORIES.values())), shape=(2,), dtype=np.float32)
    return spaces.Box(low=0.0, high=1.0, shape=(1,), dtype=np.float32)


def action_space(variant: str) -> spaces.Discrete:
    return spaces.Discrete(ACTION_COUNTS[check_variant(variant)])


#: The keywords of SortingLineEnv (and of the ids SortingLine-v0, SortingLineAdvanced-v0).
KEYWORDS = Keywords(exclude=("evolution",))


@KEYWORDS
class SortingLineEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 4}

    def __init__(self, *, render_mode: str | None = None, **keywords: Any):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode = {render_mode!r} is not valid: allowed {self.metadata['render_modes']}")
        options = KEYWORDS.line_options(keywords)
        self.variant = options.variant
        self.render_mode = render_mode
        self.observation_space = observation_space(options.variant)
        self.action_space = action_space(options.variant)
        # rclpy loads with the first env made, not with `import sorting_line_gym` (registration,
        # RL Zoo's --gym-packages); the bank itself connects only at the first reset().
        from ..ros.bank import LineBank

        self.bank = LineBank(options, watch_sensors=render_mode is not None)
        self._history = None
        self._live = None

    @property
    def namespace(self) -> str:
        """The line's namespace (with ``node="shared"``, known from the first reset on)."""
        return self.bank.namespace

    def action_masks(self) -> np.ndarray:
        """Which actions are valid now (sb3-contrib's MaskablePPO reads this): all of them on
        today's lines."""
        return action_mask(self.variant)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        # One seed reproduces a whole run: without a seed, the next node seed comes from np_random.
        node_seed = int(seed) if seed is not None else int(self.np_random.integers(0, SEED_BOUND))
        response = self.bank.reset({0: node_seed})[0]
        self._episode_start = sim_seconds(response.stamp.sec, response.stamp.nanosec)
        self._history = _History(self.bank) if self.render_mode else None
        info = {"seed": int(response.seed), "step": 0}
        if self.render_mode == "human":
            self.render()
        return observations(self.variant, response.quantity, response.category), info

    def step(self, action):
        if not self.action_space.contains(action):
            raise ValueError(f"action {action!r} is not in {self.action_space}")
        state = self.bank.step([decode_action(self.variant, action)])[0]
        obs = observations(self.variant, state.observation_quantity, state.observation_category)
        if self._history is not None:
            self._history.record(state)
        if self.render_mode == "human":
            self.render()
        stamp = state.header.stamp
        info = state_info(state, sim_seconds(stamp.sec, stamp.nanosec) - self._episode_start)
        return obs, float(state.reward), False, bool(state.truncated), info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode: pass render_mode='rgb_array' or 'human'")
            return None
        from . import render as dashboard

        frame = self.dashboard_frame()
        if self.render_mode == "rgb_array":
            return dashboard.render_dashboard(frame)
        if self._live is None:
            self._live = dashboard.LiveDashboard()
        self._live.show(frame)
        return None

    def dashboard_frame(self):
        """The episode so far as a ``render.DashboardFrame`` (for ``render.save_dashboard``);
        needs a render_mode."""
        if self._history is None:
            raise RuntimeError("dashboard_frame() needs a render_mode and a reset() first")
        env_id = self.spec.id if self.spec else ENV_IDS[self.variant]
        return self._history.frame(self.variant, env_id, self.bank.setup)

    def close(self):
        if self._live is not None:
            self._live.close()
            self._live = None
        bank = getattr(self, "bank", None)
        if bank is not None:
            bank.close()
        super().close()


class _History:
    """What the dashboard shows: the episode so far, rebuilt from the node's messages. The
    sensor readings of a tick are looked up when a frame is drawn, not when its state arrives:
    they travel on their own topics and may come later."""

    # What a reset puts on the line, the library's (src/sim/line.rs): shown before the first step.
    START_INPUT, START_BELT, START_MACHINE = (START_CONTENTS[place] for place in ("input", "belt", "machine"))

    def __init__(self, bank):
        self.bank = bank
        link = bank.links[0]
        self.states = []
        self.episode = link.tick.episode if link.tick else 0
        self.seed = None

    def record(self, state):
        self.states.append(state)
        self.seed = state.seed

    def _contents(self) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int]]:
        """(input, belt, machine) amounts (A, B) after the last recorded tick: the machine holds
        what was on the belt one tick before."""
        s = self.states
        if not s:
            return self.START_INPUT, self.START_BELT, self.START_MACHINE
        entered, belt = self.bank.sensor_readings(0, s[-1].header.stamp)
        machine = self.START_BELT
        if len(s) > 1:
            _, before = self.bank.sensor_readings(0, s[-2].header.stamp)
            machine = (before.amount_a, before.amount_b)
        return (entered.amount_a, entered.amount_b), (belt.amount_a, belt.amount_b), machine

    def frame(self, variant: str, env_id: str, setup: str):
        from .render import DashboardFrame

        s = self.states
        last = s[-1] if s else None
        input_ab, belt_ab, machine_ab = self._contents()
        return DashboardFrame(
            variant=variant,
            title=f"{env_id} setup {setup}, seed {self.seed}, episode {self.episode}",
            input_ab=input_ab,
            belt_ab=belt_ab,
            machine_ab=machine_ab,
            containers=(
                (last.container_a, last.container_a_false, last.container_b, last.container_b_false)
                if last
                else (0, 0, 0, 0)
            ),
            belt_accuracy=last.accuracy if last else START_ACCURACY,
            sorter_accuracy=s[-2].accuracy if len(s) > 1 else START_ACCURACY,
            occupancy=last.occupancy if last else START_OCCUPANCY,
            speed=last.speed if last else START_SPEED,
            mode=int(last.mode) if (last and variant == "advanced") else (0 if variant == "advanced" else None),
            purity=last.purity if last else 0.0,
            history_reward=[x.reward for x in s],
            history_speed=[x.speed for x in s],
            history_accuracy=[x.accuracy for x in s],
            history_occupancy=[x.occupancy for x in s],
            history_mode=[int(x.mode) for x in s] if variant == "advanced" else None,
            max_steps=max(EPISODE_STEPS, len(s)),
        )
