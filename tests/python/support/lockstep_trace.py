"""A lock-step line driven by `sorting_line trace` tokens (ints are actions, "r" / "rN" resets) through the
test's LineClient, and the node's states compared with the trace field by field."""

from __future__ import annotations

from support import ros_harness as h
from support.line_client import LineClient


def compare_with_trace(states_by_token: list, trace: list[dict], where: str) -> None:
    """`states_by_token[i]` is the node's state after trace line i + 1 (trace line 0 = initial reset)."""
    assert len(states_by_token) == len(trace) - 1
    for i, (state, entry) in enumerate(zip(states_by_token, trace[1:], strict=False)):
        if "reset" in entry:
            assert h.state_reset_view(state) == h.trace_reset_view(entry), f"{where}: reset #{i}"
            assert state.step == 0 and not state.truncated, f"{where}: reset #{i}"
        else:
            assert h.state_step_view(state) == h.trace_step_view(entry), f"{where}: token #{i}"


def run_tokens(c: LineClient, tokens: list) -> list:
    """Plays trace tokens on the node: ints are actions, 'r' / 'rN' resets. Returns the state after each."""
    out = []
    for t in tokens:
        if isinstance(t, str) and t.startswith("r"):
            seed = int(t[1:]) if len(t) > 1 else None
            c.reset(seed)
            out.append(c.by_stamp["state"][c.stamp][0])
        else:
            out.append(c.act(t))
    return out
