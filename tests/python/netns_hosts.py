"""Two "hosts" for discovery tests: network namespaces made by the test, joined by one veth pair, with
addresses that exist only on those two veth ends. Nothing else is reachable from them (no other
interface, no default route), and they are deleted on exit even when the test fails.

    with TwoHosts() as hosts:
        proc = hosts.popen("a", [...], env=...)   # a process inside host a
        hosts.address("a")                        # its address on the veth (e.g. 192.168.77.1)

Needs root and iproute2 (`ip netns`), like launch_scripts/test.sh's own namespace.
"""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
from typing import Optional

SUBNET = "192.168.77"  # exists only inside the namespaces made here
_COUNT = itertools.count()


def problem() -> Optional[str]:
    """None when two hosts can be made here; otherwise why not."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if not shutil.which("ip"):
        return "iproute2 (`ip`) missing"
    return None


def _ip(*args: str) -> None:
    r = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)
    if r.returncode != 0:
        raise RuntimeError(f"`ip {' '.join(args)}` failed ({r.returncode}): {r.stderr.strip()}")


class TwoHosts:
    def __init__(self) -> None:
        tag = f"sl{os.getpid()}n{next(_COUNT)}"
        self.names = {"a": f"{tag}a", "b": f"{tag}b"}
        self.devices = {"a": "veth_a", "b": "veth_b"}
        self.addresses = {"a": f"{SUBNET}.1", "b": f"{SUBNET}.2"}
        self.created: list[str] = []
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> "TwoHosts":
        try:
            for host in "ab":
                _ip("netns", "add", self.names[host])
                self.created.append(self.names[host])
            _ip("-n", self.names["a"], "link", "add", self.devices["a"], "type", "veth", "peer", "name",
                self.devices["b"], "netns", self.names["b"])
            for host in "ab":
                ns, dev = self.names[host], self.devices[host]
                _ip("-n", ns, "link", "set", dev, "addrgenmode", "none")  # no IPv6 link-local address
                _ip("-n", ns, "addr", "add", f"{self.addresses[host]}/24", "dev", dev)
                _ip("-n", ns, "link", "set", dev, "up")
                _ip("-n", ns, "link", "set", "lo", "up")
                # Multicast (DDS discovery under SUBNET) leaves by the veth, the only way out.
                _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", dev)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def address(self, host: str) -> str:
        return self.addresses[host]

    def argv(self, host: str, argv: list[str]) -> list[str]:
        """`argv` run inside `host` (ip and setpriv exec it: same pid, dies with the test process)."""
        death = ["setpriv", "--pdeathsig", "TERM", "--"] if shutil.which("setpriv") else []
        return ["ip", "netns", "exec", self.names[host], *death, *argv]

    def popen(self, host: str, argv: list[str], **kwargs) -> subprocess.Popen:
        """A process inside `host` (killed at exit if still running)."""
        p = subprocess.Popen(self.argv(host, argv), **kwargs)
        self.procs.append(p)
        return p

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=10)
        problems = []
        for name in reversed(self.created):
            try:
                _ip("netns", "del", name)
            except RuntimeError as e:
                problems.append(str(e))
        self.created.clear()
        if problems and exc[0] is None:
            raise RuntimeError("; ".join(problems))
