"""The environments: one line as a Gymnasium ``Env`` (``env``), N lines of one node as a Gymnasium
``VectorEnv`` (``vector``) and as a Stable-Baselines3 ``VecEnv`` (``sb3_vec_env``, which imports
SB3 and torch), the evolving line (``evolving``: `SortingLineEvolving-v0`), and the dashboard they render
(``render``)."""
