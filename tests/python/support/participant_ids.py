"""Which process holds which DDS participant id of a domain on this host (network namespace).

Same-host discovery under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST has no multicast (`lo` in a
namespace has none): each participant announces itself by unicast to the well-known discovery port of
each participant id of its domain (RTPS 2.5, 9.6.2.3: port 7400 + 250 * domain + 10 + 2 * id), and a
participant's id is the first one whose ports are free. Who holds which id therefore says who can
hear whom; `ss` (iproute2) tells, and `hold` takes ids away from everyone else.
"""

from __future__ import annotations

import re
import socket
import subprocess

_PB, _DG, _D1, _D3, _PG = 7400, 250, 10, 11, 2
_USERS = re.compile(r'\("([^"]+)",pid=(\d+)')


def discovery_port(domain: int, participant_id: int) -> int:
    """The well-known unicast discovery (SPDP) port of a participant id."""
    return _PB + _DG * domain + _D1 + _PG * participant_id


def user_port(domain: int, participant_id: int) -> int:
    """The well-known unicast user-traffic port of a participant id."""
    return _PB + _DG * domain + _D3 + _PG * participant_id


def holders(domain: int, ids: range = range(120)) -> dict[int, str]:
    """{participant id: "command pid"} for each id of `ids` whose discovery port a process holds."""
    by_port = {discovery_port(domain, i): i for i in ids}
    out = subprocess.run(["ss", "-uanpH"], capture_output=True, text=True, timeout=10, check=True).stdout
    found: dict[int, str] = {}
    for line in out.splitlines():
        fields = line.split()
        port = fields[3].rsplit(":", 1)[-1] if len(fields) > 3 else ""
        if port.isdigit() and int(port) in by_port:
            users = _USERS.findall(line)
            found[by_port[int(port)]] = " ".join(f"{comm} {pid}" for comm, pid in users) or "?"
    return dict(sorted(found.items()))


def hold(domain: int, count: int) -> list[socket.socket]:
    """Binds both ports of participant ids 0..count-1 (close the sockets to give them back), so that
    the next participant of `domain` on this host takes id `count` or higher."""
    held = []
    try:
        for i in range(count):
            for port in (discovery_port(domain, i), user_port(domain, i)):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                held.append(s)
                s.bind(("0.0.0.0", port))
    except OSError:
        for s in held:
            s.close()
        raise
    return held
