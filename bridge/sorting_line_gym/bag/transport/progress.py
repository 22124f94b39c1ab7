"""Progress bars of the tools that run long (replay, check): a tqdm bar on stderr where the caller
enables it (stderr is a terminal and no ``--no-progress``), or one that shows nothing."""

from __future__ import annotations


class _NoBar:
    def update(self, _n: int) -> None:
        pass

    def close(self) -> None:
        pass


def progress_bar(total: int, enabled: bool, desc: str = "replay", unit: str = "msg"):
    """A tqdm bar on stderr (the caller enables it where stderr is a terminal), or nothing."""
    if not enabled:
        return _NoBar()
    # Imported only for a bar: tqdm is an optional dependency (the train extra), not needed without one.
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=False)
