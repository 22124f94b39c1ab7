"""Exact structural equality of trajectories (numpy arrays by value and dtype, dicts, lists and tuples by
type), and where two of them first differ: for comparing envs, backends and vectorizers run for run."""

from __future__ import annotations

import numpy as np


def same(a, b) -> bool:
    """Exact structural equality of trajectories (arrays by value, dtype included)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and bool(np.all(a == b))
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=False))
    return type(a) is type(b) and a == b


def first_difference(a: list, b: list, equal=None) -> str:
    """Where two runs first differ, by ``equal`` (default: ``same``)."""
    equal = equal or same
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if not equal(x, y):
            return f"entry {i}: {x!r}\n    vs {y!r}"
    return f"lengths {len(a)} vs {len(b)}"
