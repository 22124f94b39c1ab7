"""Training with Stable-Baselines3: `sorting-line-train` (``train``), the hyperparameter files and
their overrides (``hyperparams``, ``hyperparams/<algo>.yml``), and the callback that logs the line's
KPIs (``callbacks``), and the transfer study of the evolving line (``transfer``:
`sorting-line-transfer`). RL Zoo's conf files built from the same YAML are ``sorting_line_gym.zoo``."""
