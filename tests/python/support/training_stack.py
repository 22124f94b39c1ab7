"""Which tests need the training stack (torch, SB3, sb3-contrib, onnx: `launch_scripts/setup.sh --train`).

The suite runs with it (launch_scripts/test.sh sets .venv up with --train), and there a missing package
fails the test that imports it. launch_scripts/test.sh also runs a subset in a core venv (the other
Python version, set up without --train) and says so with SORTING_LINE_CORE_VENV=1: only then do the
tests marked ``@needs_training`` skip, naming what is missing.
"""

from __future__ import annotations

import importlib.util
import os

import pytest

#: What training imports and a core venv lacks.
TRAINING_MODULES = ("torch", "stable_baselines3", "sb3_contrib", "onnx")

CORE_VENV = os.environ.get("SORTING_LINE_CORE_VENV") == "1"
MISSING = [m for m in TRAINING_MODULES if importlib.util.find_spec(m) is None] if CORE_VENV else []

needs_training = pytest.mark.skipif(
    bool(MISSING), reason=f"needs the training stack (setup.sh --train); this core venv lacks {', '.join(MISSING)}"
)
