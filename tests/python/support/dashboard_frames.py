"""Plausible dashboard frames for the renderer's tests (unit/test_render.py), also built in the
subprocesses those tests start (headless, and with pyplot's Agg backend as the window)."""

from __future__ import annotations

import numpy as np

from sorting_line_gym.envs.render import DashboardFrame
from sorting_line_gym.line.vocabulary import EPISODE_STEPS, SPEEDS, START_ACCURACY, START_SPEED


def make_frame(variant: str, steps: int, seed: int = 0, **overrides) -> DashboardFrame:
    """A plausible tick after `steps` steps (steps = 0: right after reset, empty histories)."""
    rng = np.random.default_rng(seed)
    speed = [float(rng.choice(SPEEDS)) for _ in range(steps)]
    accuracy = [float(a) for a in rng.uniform(0.4, 0.98, steps)]
    occupancy = [float(o) for o in rng.uniform(0.05, 0.95, steps)]
    reward = [
        -0.1 if a < 0.7 else round(0.5 * (a - 0.7) / 0.3 + 0.5 * (s - 0.1) / 0.9, 2)
        for a, s in zip(accuracy, speed, strict=False)
    ]
    advanced = variant == "advanced"
    modes = [int(m) for m in rng.integers(0, 3, steps)] if advanced else None
    containers = (40 * steps, 5 * steps, 35 * steps, 6 * steps) if steps else (0, 0, 0, 0)
    sorted_units = sum(containers)
    fields = dict(
        variant=variant,
        title=f"SortingLine-v0 setup B ({variant}), seed 42, episode 3",
        input_ab=(30, 45),
        belt_ab=(70, 12),
        machine_ab=(5, 60),
        containers=containers,
        belt_accuracy=accuracy[-1] if steps else START_ACCURACY,
        sorter_accuracy=START_ACCURACY,
        occupancy=0.82,
        speed=speed[-1] if steps else START_SPEED,
        mode=(modes[-1] if steps else 0) if advanced else None,
        purity=(containers[0] + containers[2]) / sorted_units if sorted_units else 0.0,
        history_reward=reward,
        history_speed=speed,
        history_accuracy=accuracy,
        history_occupancy=occupancy,
        history_mode=modes,
        max_steps=EPISODE_STEPS,
    )
    fields.update(overrides)
    return DashboardFrame(**fields)
