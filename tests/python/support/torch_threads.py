"""One torch thread for a test module, as sorting-line-train runs: on a busy machine a second one only waits.
The fixture ``one_torch_thread`` of both tiers' conftest.py is this; a module asks for it with
``pytestmark = pytest.mark.usefixtures("one_torch_thread")``."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator


@contextlib.contextmanager
def one_torch_thread() -> Iterator[None]:
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
