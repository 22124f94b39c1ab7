"""What every run of a controller check takes, open loop or closed loop: handed from
:func:`~.checker.check_controller` to :mod:`.open_loop` and :mod:`.closed_loop` as one type."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from .controller_process import ControllerProcess


def _never() -> bool:
    return False


@dataclass
class RunOptions:
    """``answer_timeout``: longest wait for one tick's answer (s); ``wait``: longest wait for the
    controller to appear (s); ``process``: the controller the check started (None: one already
    running); ``stop``: asked often, True ends the run early (SIGINT); ``progress``: a progress bar."""

    answer_timeout: float
    wait: float
    process: ControllerProcess | None = None
    stop: Callable[[], bool] = field(default=_never)
    progress: bool = False
