"""The "hosts" of multi-host tests: network namespaces made by the test, each with one veth "cable"
plugged into a Linux bridge (the "switch", in a namespace of its own), with addresses that exist
only on those veth ends (192.168.77.1, .2, ... in the order the hosts are named). Nothing else is
reachable from them (no other interface, no default route), and they are all deleted on exit, even
when the test fails.

    with Hosts(["a", "b", "trainer"]) as hosts:
        proc = hosts.popen("a", [...], env=...)   # a process inside host a
        hosts.address("a")                        # its address (192.168.77.1)
        hosts.unplug("a"); hosts.plug("a")        # its cable out of the switch, and back in

``TwoHosts()`` is ``Hosts(["a", "b"])``. Needs root and iproute2 (`ip netns`), like
launch_scripts/test.sh's own namespace.
"""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
from collections.abc import Sequence

SUBNET = "192.168.77"  # exists only inside the namespaces made here
MULTICAST = "224.0.0.0/4"
_COUNT = itertools.count()


def problem() -> str | None:
    """None when hosts can be made here; otherwise why not."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if not shutil.which("ip"):
        return "iproute2 (`ip`) missing"
    return None


def _ip(*args: str) -> None:
    r = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)
    if r.returncode != 0:
        raise RuntimeError(f"`ip {' '.join(args)}` failed ({r.returncode}): {r.stderr.strip()}")


class Hosts:
    """One namespace per name in ``hosts`` (at most 200), plus the switch's namespace."""

    DEVICE = "eth0"  # each host's end of its cable

    def __init__(self, hosts: Sequence[str]) -> None:
        if not 1 <= len(hosts) <= 200 or len(set(hosts)) != len(hosts):
            raise ValueError(f"hosts = {list(hosts)}: want 1 ..= 200 distinct names")
        tag = f"sl{os.getpid()}n{next(_COUNT)}"
        self.hosts = list(hosts)
        self.names = {host: f"{tag}h{i}" for i, host in enumerate(self.hosts)}
        self.switch = f"{tag}sw"
        self.ports = {host: f"port{i}" for i, host in enumerate(self.hosts)}  # the switch's ends
        self.addresses = {host: f"{SUBNET}.{i + 1}" for i, host in enumerate(self.hosts)}
        self.created: list[str] = []
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> Hosts:
        try:
            _ip("netns", "add", self.switch)
            self.created.append(self.switch)
            _ip("-n", self.switch, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0")
            _ip("-n", self.switch, "link", "set", "br0", "addrgenmode", "none")  # the switch has no address
            _ip("-n", self.switch, "link", "set", "br0", "up")
            for host in self.hosts:
                ns, port = self.names[host], self.ports[host]
                _ip("netns", "add", ns)
                self.created.append(ns)
                _ip("-n", self.switch, "link", "add", port, "type", "veth", "peer", "name", self.DEVICE, "netns", ns)
                _ip("-n", self.switch, "link", "set", port, "addrgenmode", "none")
                _ip("-n", self.switch, "link", "set", port, "master", "br0")
                _ip("-n", self.switch, "link", "set", port, "up")
                _ip("-n", ns, "link", "set", self.DEVICE, "addrgenmode", "none")  # no IPv6 link-local address
                _ip("-n", ns, "addr", "add", f"{self.addresses[host]}/24", "dev", self.DEVICE)
                _ip("-n", ns, "link", "set", self.DEVICE, "up")
                _ip("-n", ns, "link", "set", "lo", "up")
                # Multicast (DDS discovery under SUBNET) leaves by the cable, the only way out.
                _ip("-n", ns, "route", "add", MULTICAST, "dev", self.DEVICE)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def address(self, host: str) -> str:
        return self.addresses[host]

    def argv(self, host: str, argv: list[str]) -> list[str]:
        """`argv` run inside `host` (ip and setpriv exec it: same pid, dies with the test process)."""
        from sorting_line_gym.line.process import with_parent_death_signal

        return ["ip", "netns", "exec", self.names[host], *with_parent_death_signal(argv)]

    def popen(self, host: str, argv: list[str], **kwargs) -> subprocess.Popen:
        """A process inside `host` (killed at exit if still running)."""
        p = subprocess.Popen(self.argv(host, argv), **kwargs)
        self.procs.append(p)
        return p

    def unplug(self, host: str) -> None:
        """Takes `host`'s cable out of the switch (its port down): the host keeps its address and
        its processes, and nothing reaches it or leaves it."""
        _ip("-n", self.switch, "link", "set", self.ports[host], "down")

    def plug(self, host: str) -> None:
        """Puts `host`'s cable back (and its multicast route, should the kernel have dropped it)."""
        _ip("-n", self.switch, "link", "set", self.ports[host], "up")
        _ip("-n", self.names[host], "route", "replace", MULTICAST, "dev", self.DEVICE)

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


def TwoHosts() -> Hosts:
    """Hosts a and b (192.168.77.1 and .2)."""
    return Hosts(["a", "b"])
