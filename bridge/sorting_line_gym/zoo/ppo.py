"""RL Zoo conf file (``--conf-file sorting_line_gym.zoo.ppo``): see ``sorting_line_gym.zoo``."""

from . import zoo_hyperparams

hyperparams = zoo_hyperparams("ppo")
