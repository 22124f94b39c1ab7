"""Training with Stable-Baselines3: `sorting-line-train` (``train``), the hyperparameter files and
their overrides (``hyperparams``, ``hyperparams/<algo>.yml``), and the callback that logs the line's
KPIs (``callbacks``), SB3 models as agents (``trained_agent``), the ONNX export (``export``) and
Ray RLlib (``rllib``). The studies that train many models (the benchmark, the transfer study) are
``sorting_line_gym.studies``. RL Zoo's conf files built from the same YAML are ``sorting_line_gym.zoo``."""
