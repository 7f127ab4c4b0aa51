"""Which process holds a local port: for the message that refuses a port already in use
(a second `groundfx sitl` beside a first, a PX4 SITL on 14540). Linux's /proc only; elsewhere
the message names the port alone."""

from __future__ import annotations

from pathlib import Path

PROC = Path("/proc")


def socket_inodes(table: str, port: int) -> set[str]:
    """Inodes of the sockets bound to `port` in a /proc/net/{udp,tcp} table's text."""
    inodes = set()
    for line in table.splitlines()[1:]:
        fields = line.split()
        if len(fields) > 9 and int(fields[1].rsplit(":", 1)[1], 16) == port:
            inodes.add(fields[9])
    return inodes


def port_owner(port: int, protocol: str = "udp", proc: Path = PROC) -> str | None:
    """ "pid N: COMMAND LINE" of a process holding `port`, or None if it cannot be told."""
    inodes: set[str] = set()
    for name in (protocol, protocol + "6"):
        try:
            inodes |= socket_inodes((proc / "net" / name).read_text(), port)
        except OSError:
            continue
    if not inodes:
        return None
    targets = {f"socket:[{inode}]" for inode in inodes}
    for pid_dir in proc.iterdir():
        if not pid_dir.name.isdigit():
            continue
        try:
            for fd in (pid_dir / "fd").iterdir():
                if fd.readlink().as_posix() in targets:
                    cmdline = (pid_dir / "cmdline").read_bytes().replace(b"\0", b" ")
                    return f"pid {pid_dir.name}: {cmdline.decode(errors='replace').strip()}"
        except OSError:  # gone, or not ours to look into
            continue
    return None
