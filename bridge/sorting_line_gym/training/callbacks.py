"""Stable-Baselines3 callback that logs the line's KPIs during training.

SB3 logs the episode reward and length (``rollout/ep_rew_mean``) through VecMonitor; an operator
wants to see what the agent does to the line as well. At the end of every training episode this
records, under ``line/`` (TensorBoard, and the console log with ``verbose=1``), averaged over the
episodes since the last dump:

- ``line/purity``: purity of the containers at the episode's end (correct / all sorted);
- ``line/mean_speed``: the belt speed averaged over the episode's steps;
- ``line/mean_accuracy``: the sorting accuracy averaged over the steps;
- ``line/speed_changes``: how often the belt speed changed (each change costs the penalty in B, D);
- ``line/below_threshold``: share of steps whose accuracy was under the threshold (reward -0.1).
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from ..line.vocabulary import THRESHOLD


class LineKpiCallback(BaseCallback):
    def __init__(self, threshold: float = THRESHOLD, verbose: int = 0):
        super().__init__(verbose)
        self.threshold = threshold
        self.episodes = 0

    def _on_training_start(self) -> None:
        n = self.training_env.num_envs
        self._speed = np.zeros(n)
        self._accuracy = np.zeros(n)
        self._below = np.zeros(n)
        self._steps = np.zeros(n)

    def _on_step(self) -> bool:
        infos = self.locals["infos"]
        dones = self.locals["dones"]
        for k, info in enumerate(infos):
            self._speed[k] += info["speed"]
            self._accuracy[k] += info["accuracy"]
            self._below[k] += info["accuracy"] < self.threshold
            self._steps[k] += 1
            if dones[k]:
                steps = self._steps[k]
                self.logger.record_mean("line/purity", info["purity"])
                self.logger.record_mean("line/mean_speed", self._speed[k] / steps)
                self.logger.record_mean("line/mean_accuracy", self._accuracy[k] / steps)
                self.logger.record_mean("line/below_threshold", self._below[k] / steps)
                self.logger.record_mean("line/speed_changes", info["speed_changes"])
                self._speed[k] = self._accuracy[k] = self._below[k] = self._steps[k] = 0
                self.episodes += 1
        return True
