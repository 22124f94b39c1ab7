"""Published figures to compare against: the paper's Table 1 and the reference implementation's.

- :data:`TABLE_1`: the SortingEnv paper's Table 1: per
  setup, variant and algorithm, the mean speed and mean purity (both in %) and the mean reward,
  as printed. The paper has no random-agent rows and no ``rba-hold`` (ours).
- :data:`REFERENCE`: what the reference implementation gives on the paper's evaluation protocol
  (seeds 42..51, 50 steps), measured on its code (docs/results/reference-comparison.md):
  its RBA and its (unseeded) random agent on all eight setups, and PPO on B advanced. Each value
  is (mean, population std) of the episode reward.
"""

from __future__ import annotations

from ..line.vocabulary import SETUPS, VARIANTS

#: (setup, variant, algorithm) -> (speed %, purity %, reward), as printed in the paper's Table 1.
TABLE_1: dict[tuple[str, str, str], tuple[float, float, float]] = {
    ("A", "basic", "rba"): (55, 85, 26.56),
    ("A", "basic", "dqn"): (44, 85, 23.9),
    ("A", "basic", "ppo"): (53, 85, 26.32),
    ("A", "basic", "a2c"): (45, 85, 24.39),
    ("A", "advanced", "rba"): (59, 94, 36.48),
    ("A", "advanced", "dqn"): (40, 93.5, 31.01),
    ("A", "advanced", "ppo"): (55, 94, 35.29),
    ("A", "advanced", "a2c"): (50, 94, 34.12),
    ("B", "basic", "rba"): (72, 83.5, 11.95),
    ("B", "basic", "dqn"): (53, 80.5, 23.46),
    ("B", "basic", "ppo"): (66, 83.5, 28.06),
    ("B", "basic", "a2c"): (50, 53, 18.33),
    ("B", "advanced", "rba"): (77, 91.5, 27.33),
    ("B", "advanced", "dqn"): (48, 91.5, 30.23),
    ("B", "advanced", "ppo"): (68, 91.5, 36.85),
    ("B", "advanced", "a2c"): (44, 91.5, 30.61),
    ("C", "basic", "rba"): (55, 73.5, 19.77),
    ("C", "basic", "dqn"): (42, 85, 23.34),
    ("C", "basic", "ppo"): (47, 84, 23.79),
    ("C", "basic", "a2c"): (48, 83, 23.1),
    ("C", "advanced", "rba"): (61, 85, 29.5),
    ("C", "advanced", "dqn"): (41, 93, 31),
    ("C", "advanced", "ppo"): (49, 93.5, 33.62),
    ("C", "advanced", "a2c"): (50, 92, 32.74),
    ("D", "basic", "rba"): (73, 76, 10.21),
    ("D", "basic", "dqn"): (53, 77, 22.98),
    ("D", "basic", "ppo"): (64, 64, 21.62),
    ("D", "basic", "a2c"): (50, 53, 18.33),
    ("D", "advanced", "rba"): (78, 83, 22.83),
    ("D", "advanced", "dqn"): (49, 89.5, 27.96),
    ("D", "advanced", "ppo"): (69, 91.5, 35.53),
    ("D", "advanced", "a2c"): (50, 69.5, 25.67),
}

#: Row labels of Table 1 ("A1" ... "D8"), in the paper's order.
TABLE_1_INDEX: dict[tuple[str, str, str], str] = {
    (setup, variant, algo): f"{setup}{i + 1 + (4 if variant == 'advanced' else 0)}"
    for setup in SETUPS
    for variant in VARIANTS
    for i, algo in enumerate(("rba", "dqn", "ppo", "a2c"))
}

#: (setup, variant, agent) -> (mean, std) of the episode reward of the reference implementation.
REFERENCE: dict[tuple[str, str, str], tuple[float, float]] = {
    ("A", "basic", "rba"): (27.02, 0.93),
    ("A", "advanced", "rba"): (36.71, 0.93),
    ("B", "basic", "rba"): (12.55, 4.35),
    ("B", "advanced", "rba"): (22.58, 3.29),
    ("C", "basic", "rba"): (21.07, 2.34),
    ("C", "advanced", "rba"): (30.18, 2.18),
    ("D", "basic", "rba"): (6.41, 4.77),
    ("D", "advanced", "rba"): (16.28, 5.60),
    ("A", "basic", "random"): (10.76, 2.21),
    ("A", "advanced", "random"): (9.18, 2.24),
    ("B", "basic", "random"): (-1.20, 1.93),
    ("B", "advanced", "random"): (-2.66, 1.77),
    ("C", "basic", "random"): (10.76, 2.21),
    ("C", "advanced", "random"): (9.18, 2.24),
    ("D", "basic", "random"): (-1.20, 1.93),
    ("D", "advanced", "random"): (-2.66, 1.77),
    ("B", "advanced", "ppo"): (30.86, 3.76),
}
