"""Cells of a study run as tasks of a Ray cluster (``--ray ADDRESS`` of the benchmark and the
transfer study), where ``cell_pool`` runs them in worker processes of this machine.

The driver (the study's process) keeps the cell store and the resume: it asks the cluster only for
the cells that are not saved yet. A task runs one unit (a cell, or a batch of seeds) on whichever
host Ray puts it, in a scratch directory of that host standing in for the study's ``--out``:
workers on other hosts do not share the driver's filesystem. The files the study needs there
(``inputs``, such as the transfer study's schedules) go with the task; what the unit writes there
(models, training records, TensorBoard logs) comes back with its result, paths in it rewritten from
the scratch directory to ``--out``, and the driver writes it under ``--out`` before it saves the
cells, so that a saved cell's models are always there. Each record gets ``ran_on``: the host, its
IP address, the Ray node id and the process that ran it.

A task asks for one CPU and is spread over the nodes (a cell is minutes of work, so packing them on
one node first would only queue them); as many run at once as the cluster has CPUs. Ray starts
its workers with ``exec``, never by forking the driver (rclpy is not fork-safe), and reuses them
cell after cell as the cell pool does, so each declares itself a process that outlives its envs
(``workarounds.participant_deletion_hang``). Ctrl-C or SIGTERM cancels the tasks (their worker
processes are killed, their nodes with them through the parent-death signal) and goes on up.

Ray is imported only here and only with ``--ray``: one machine without it needs no Ray.
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

#: What installs Ray into the project's venv (launch_scripts/requirements-rllib.txt).
INSTALL_HINT = "bash launch_scripts/setup.sh --rllib (launch_scripts/requirements-rllib.txt)"
#: How long the driver waits for the address to answer, then for Ray's handshake with it.
PROBE_TIMEOUT_S = 10.0
CONNECT_TIMEOUT_S = 60.0
#: Ray Client's port when a ray:// address names none (`ray start --head`'s default).
CLIENT_PORT = 10001
#: The files of a unit that are cell records: the driver saves those from the results, not as files.
RECORDS_DIR = "cells"
#: How often the driver wakes from waiting on the tasks, so that Ctrl-C and SIGTERM act at once.
POLL_S = 1.0


class ClusterError(RuntimeError):
    """Ray is missing, or the cluster's address is malformed or does not answer."""


def endpoint(address: str) -> tuple[str, int] | None:
    """The (host, port) that ``address`` names, to probe before Ray's own connection; None for
    ``auto`` (the cluster this host's ``ray start`` joined). Raises ClusterError for another form."""
    if address == "auto":
        return None
    rest = address.removeprefix("ray://")
    host, _, port = rest.rpartition(":") if ":" in rest else (rest, "", "")
    if not port and address.startswith("ray://"):
        host, port = rest, str(CLIENT_PORT)
    host = host.strip("[]")  # an IPv6 address as [::1]:6379
    if not host or not port.isdigit() or not 0 < int(port) < 65536 or "/" in host:
        raise ClusterError(
            f"--ray {address} is not valid: allowed HOST:PORT (the head's GCS, from a node of the cluster), "
            "ray://HOST[:PORT] (Ray Client, from any machine) or auto"
        )
    return host, int(port)


def connect(address: str, probe_timeout: float = PROBE_TIMEOUT_S, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Joins this process to the Ray cluster at ``address`` as its driver; raises ClusterError
    naming the address (or the command that installs Ray) when that cannot be done in time."""
    try:
        import ray
    except ImportError as e:
        raise ClusterError(f"--ray needs Ray, which is not installed in {sys.executable} ({e}): {INSTALL_HINT}") from e
    found = endpoint(address)
    if found is not None:
        try:
            socket.create_connection(found, timeout=probe_timeout).close()
        except OSError as e:
            raise ClusterError(f"--ray {address}: nothing answers at {found[0]}:{found[1]} ({e})") from e
    # An address that answers but is not a Ray cluster can keep ray.init waiting: bounded here
    # (the thread is a daemon, so a refused start does not wait for it to give up).
    failure: list[BaseException] = []
    # In a thread ray.init installs no SIGTERM handler, and says so as a warning: that is wanted
    # (the study's own handler stops it, cancelling the tasks), so the warning is dropped.
    logging.getLogger("ray._private.worker").addFilter(lambda r: "SIGTERM handler is not set" not in r.getMessage())

    def init() -> None:
        try:
            ray.init(address=address, logging_level="WARNING")
        except BaseException as e:  # noqa: BLE001 - handed to the caller below
            failure.append(e)

    joiner = threading.Thread(target=init, name="ray-init", daemon=True)
    joiner.start()
    joiner.join(timeout)
    if joiner.is_alive():
        raise ClusterError(f"--ray {address}: no Ray cluster answered within {timeout:.0f} s")
    if failure:
        raise ClusterError(f"--ray {address}: Ray could not join the cluster: {failure[0]}") from failure[0]


def _rewritten(value: Any, scratch: str, out: str) -> Any:
    """``value`` with every path under ``scratch`` in its strings (a model's path, an agent's
    ``algo:path``) made the same path under ``out``, as ``Path(out) / relative`` spells it, in
    dicts, lists and tuples."""
    if isinstance(value, str):
        return _moved(value, scratch, out)
    if isinstance(value, dict):
        return {k: _rewritten(v, scratch, out) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_rewritten(v, scratch, out) for v in value)
    return value


def _moved(text: str, scratch: str, out: str) -> str:
    """``text`` with the paths under ``scratch`` made paths under ``out`` (``Path(".") / "models"``
    is ``models``, so under ``.`` the prefix goes away)."""
    prefix = "" if out == "." else out + "/"
    return text.replace(scratch + "/", prefix).replace(scratch, out)


def _where() -> dict[str, Any]:
    """Which host, Ray node and process this is."""
    import ray

    return {
        "host": socket.gethostname(),
        "ip": ray.util.get_node_ip_address(),
        "node_id": ray.get_runtime_context().get_node_id(),
        "pid": os.getpid(),
    }


def run_unit(function: Callable, arguments: tuple, out: Path, inputs: dict[str, bytes]) -> dict[str, Any]:
    """In a Ray worker: ``function(*arguments)`` with ``out`` among the arguments replaced by a
    scratch directory holding ``inputs``; returns its result (paths under the scratch directory
    rewritten to ``out``), the files it wrote there (but the cell records) and where it ran."""
    import shutil
    import tempfile

    from ..workarounds.participant_deletion_hang import outlives_its_envs

    outlives_its_envs()  # cell after cell in this worker, as the cell pool's
    scratch = Path(tempfile.mkdtemp(prefix="sorting_line_cell_"))
    try:
        for name, data in inputs.items():
            (scratch / name).parent.mkdir(parents=True, exist_ok=True)
            (scratch / name).write_bytes(data)
        result = function(*(scratch if a == out else a for a in arguments))
        files = {}
        for path in sorted(p for p in scratch.rglob("*") if p.is_file()):
            name = path.relative_to(scratch).as_posix()
            data = path.read_bytes()
            if name.startswith(RECORDS_DIR + "/") or inputs.get(name) == data:
                continue
            if path.suffix in (".json", ".yaml", ".yml", ".txt", ".md", ".csv"):
                text = _moved(data.decode(errors="surrogateescape"), str(scratch), str(out))
                data = text.encode(errors="surrogateescape")
            files[name] = data
        return {"result": _rewritten(result, str(scratch), str(out)), "files": files, "ran_on": _where()}
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _marked(result: Any, ran_on: dict[str, Any]) -> Any:
    """The unit's record, or each of its records, with ``ran_on``."""
    if isinstance(result, dict):
        return {**result, "ran_on": ran_on}
    if isinstance(result, list):
        return [_marked(r, ran_on) for r in result]
    return result


def _write_files(out: Path, files: dict[str, bytes]) -> None:
    """A unit's files under ``out``, each through a temporary file and a rename (whole or absent)."""
    for name, data in files.items():
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)


def capacity() -> int:
    """How many units to have in the cluster at once: its CPUs (one per task), at least one."""
    import ray

    return max(1, int(ray.cluster_resources().get("CPU", 0)))


def run_on_cluster(
    todo: Iterable[Any],
    call: Callable[[Any], tuple],
    out: Path,
    finished: Callable[[Any, Any], None],
    running: Callable[[list[Any]], None] = lambda items: None,
    inputs: dict[str, bytes] | None = None,
) -> None:
    """As ``cell_pool.run_parallel``, on the cluster ``connect`` joined: ``call(item)`` =
    (function, *arguments), ``out`` among the arguments standing for the study's results
    directory; ``finished(item, result or exception)`` here as each ends, after its files are
    written under ``out``. A KeyboardInterrupt cancels the tasks and goes on up."""
    import ray

    task = ray.remote(num_cpus=1, scheduling_strategy="SPREAD")(run_unit)
    shared = ray.put(inputs or {})
    pending: dict[Any, Any] = {}
    queue = list(todo)
    try:
        while queue or pending:
            if queue and len(pending) < capacity():
                while queue and len(pending) < capacity():
                    item = queue.pop(0)
                    function, *arguments = call(item)
                    pending[task.remote(function, tuple(arguments), out, shared)] = item
                running(list(pending.values()))
            complete, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_S)
            for ref in complete:
                item = pending.pop(ref)
                try:
                    done = ray.get(ref)
                except Exception as e:  # noqa: BLE001 - report every failed unit, keep the others
                    finished(item, e)
                    continue
                _write_files(out, done["files"])
                finished(item, _marked(done["result"], done["ran_on"]))
            if complete:
                running(list(pending.values()))
    except KeyboardInterrupt:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
