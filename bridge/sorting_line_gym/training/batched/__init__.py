"""The batched trainer (issue 54): S independent seeds of one SB3 algorithm trained at once in one
process, on S x L lines stepped in one call (native by default, or one node's), with the S
networks evaluated and updated as one batched computation. Each seed stays a run of its own (its
initial weights, RNG, optimizer state, gradient clipping and episode bookkeeping), and every
mirrored piece names the SB3 code it is held to, so that a seed's update equals SB3's for that
seed.

One concept per module:

- ``params``: S SB3 networks as stacked JAX arrays (a leading seed axis) and one seed's forward
  pass; ``optim``: torch's Adam, RMSprop and gradient-norm clip as per-seed JAX functions, their
  state moved from and to S torch optimizers; ``torch_math``: tanh, exp, logsumexp and softmax
  as torch rounds them (the base of the JAX learners: jit + vmap over seeds);
- ``lines``: the S x L lines (native, or a node's over ROS), seeded, auto-reset and counted per
  seed as SB3's VecEnv;
- ``checks``: what the trainer accepts (algorithms, seeds, hyperparameters, memory);
- ``models``: the SB3 models behind the seeds (built, loaded, written back as SB3's zips);
- ``actor_critic``, ``rollout``, ``ppo``, ``a2c``: SB3's actor-critic policy, rollout buffer
  (GAE, the truncation bootstrap), PPO/MaskablePPO and A2C updates, for S seeds;
- ``on_policy``: the driver, ``OnPolicyTrainer`` (PPO, A2C, MaskablePPO);
- ``dqn`` (``BatchedDQN``), ``q_learning`` and ``replay``: DQN's driver, its arithmetic in JAX
  (greedy actions, SB3's loss, the gradient steps and the target update) and its replay buffers,
  for S seeds.

``training.train_batched`` puts both behind ``sorting-line-train --engine batched --seeds ...``.

This package sits below ``training`` in docs/layout.md's layers (``training/batched``): it may
use ``envs``, ``agents`` and ``line`` but not ``training``'s modules (``train`` imports it, not
the other way). Importing the package loads nothing heavy; torch and SB3 load with the modules
that need them.
"""
