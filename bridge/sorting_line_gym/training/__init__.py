"""Training and studies on the line (the package reorganisation moves train, hyperparams and
callbacks here)."""
