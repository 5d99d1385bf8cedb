"""The process holding a REST lease, where the server can prove which one it is.

A client on the same machine may declare its process id when it takes the lease. The
server believes it only when that process owns the very TCP connection the request came
on (its socket's inode among the process's open files, Linux /proc), so a wrong pid, a pid
from another pid namespace, or a client on another machine is never watched. The process
is then gone, provably, when /proc no longer has it, when it is a zombie (exited, not yet
reaped), or when its pid now names a process started at another time. Anywhere /proc does
not answer, nothing is proved and the lease lives out its TTL.
"""

from __future__ import annotations

import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path

PROC = Path("/proc")
# /proc/<pid>/stat, after the ")" that ends the command name: state is the 1st field and
# starttime (clock ticks since boot) the 20th
_STAT_STATE = 0
_STAT_STARTTIME = 19
_EXITED_STATES = frozenset({"Z", "X"})  # zombie, dead


@dataclass(frozen=True)
class HolderProcess:
    pid: int
    started_ticks: int

    def gone(self) -> bool:
        stat = _stat(self.pid)
        return stat is None or stat[0] in _EXITED_STATES or stat[1] != self.started_ticks


def verified_holder(pid: int, client_host: str, client_port: int) -> HolderProcess | None:
    """The process ``pid``, if it is alive and owns the connection from
    ``client_host:client_port`` to this server; None when that cannot be shown."""
    try:
        address = ipaddress.ip_address(client_host)
    except ValueError:
        return None
    if not address.is_loopback:
        return None
    stat = _stat(pid)
    if stat is None or stat[0] in _EXITED_STATES:
        return None
    inodes = _socket_inodes(address, client_port)
    if not inodes or not _owns_any(pid, inodes):
        return None
    return HolderProcess(pid, stat[1])


def _stat(pid: int) -> tuple[str, int] | None:
    try:
        text = (PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    fields = text[text.rfind(")") + 2 :].split()
    try:
        return fields[_STAT_STATE], int(fields[_STAT_STARTTIME])
    except (IndexError, ValueError):
        return None


def _proc_net_address(address: ipaddress.IPv4Address | ipaddress.IPv6Address, port: int) -> str:
    """An address as /proc/net/tcp{,6} writes it: the bytes of each 32-bit word in host
    (little-endian) order, then the port, all hex."""
    packed = address.packed
    words = [packed[i : i + 4][::-1] for i in range(0, len(packed), 4)]
    return f"{b''.join(words).hex().upper()}:{port:04X}"


def _socket_inodes(address: ipaddress.IPv4Address | ipaddress.IPv6Address, port: int) -> set[str]:
    """The inodes of the TCP sockets whose local end is ``address:port`` (the client's
    end of its connection to this server)."""
    table = "tcp6" if address.version == 6 else "tcp"
    local = _proc_net_address(address, port)
    try:
        lines = (PROC / "net" / table).read_text().splitlines()[1:]
    except OSError:
        return set()
    inodes = set()
    for line in lines:
        fields = line.split()
        if len(fields) > 9 and fields[1] == local:
            inodes.add(fields[9])
    return inodes


def _owns_any(pid: int, inodes: set[str]) -> bool:
    wanted = {f"socket:[{inode}]" for inode in inodes}
    try:
        with os.scandir(PROC / str(pid) / "fd") as entries:
            for entry in entries:
                try:
                    if os.readlink(entry.path) in wanted:
                        return True
                except OSError:
                    continue
    except OSError:
        return False
    return False
