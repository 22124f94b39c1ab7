"""Checks that a written figure is a real image: a PNG of some size with more than a blank canvas in it."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def assert_real_image(path: Path, min_bytes: int = 10_000) -> None:
    """A PNG that is more than a blank canvas."""
    import matplotlib.image

    assert path.is_file() and path.stat().st_size >= min_bytes, f"{path} missing or tiny"
    pixels = matplotlib.image.imread(path)
    assert pixels.ndim == 3 and pixels.shape[0] > 200 and pixels.shape[1] > 200
    assert len(np.unique(pixels.reshape(-1, pixels.shape[2]), axis=0)) > 50, f"{path} is nearly uniform"
