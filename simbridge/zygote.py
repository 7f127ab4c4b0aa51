"""Flight processes started warm. A flight is two processes (`groundfx sim` and `groundfx
autopilot`), and a fresh interpreter spends about 0.4 CPU-s importing what each runs before
its first step. A zygote, one interpreter per launching process, imports that once and forks
a child for each `python -m MODULE ...` asked of it: a real process with its own pid, pipes,
process group, title and exit status, that runs MODULE as `python -m` would.

`popen(args, preload, ...)` is `subprocess.Popen(args, ...)` for such a command; `preload`
names what the command imports, which the zygote imports before it forks (once). Anything
else, or GROUNDFX_WARM_START=0, is started as asked. The zygote reports each child's exit
status over a socket of its own; it ends when the process that started it exits."""

from __future__ import annotations

import atexit
import contextlib
import importlib
import json
import os
import runpy
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from typing import Any

import setproctitle

WARM_ENV = "GROUNDFX_WARM_START"
_PID = struct.Struct("q")
_STATUS = struct.Struct("qd")  # exit code (Popen's: -N for signal N), CPU seconds
_MAX_REQUEST = 1 << 20


def popen(args: Sequence[str], preload: Sequence[str], **options: Any) -> subprocess.Popen[str]:
    """`subprocess.Popen(args, **options)`, forked from this process's zygote where `args` is
    `[sys.executable, "-m", MODULE, ...]` and the options are pipes, `env`, `cwd`, `text`
    and `process_group` only. `preload`: the modules the command imports (none that starts a
    thread: a zygote holds none when it forks)."""
    args = list(args)
    if _warm_start_possible(args, options):
        try:
            return WarmProcess(_zygote(), args, tuple(preload), **options)
        except OSError as err:  # no zygote to fork from (it failed): a fresh interpreter
            print(f"groundfx: starting {args[2]} cold: {err}", file=sys.stderr)
    return subprocess.Popen(args, **options)


def _warm_start_possible(args: list[str], options: dict[str, Any]) -> bool:
    allowed = {"stdin", "stdout", "stderr", "text", "env", "cwd", "process_group", "bufsize"}
    return (
        os.environ.get(WARM_ENV, "1") != "0"
        and sys.platform.startswith("linux")
        and len(args) >= 3
        and args[:2] == [sys.executable, "-m"]
        and set(options) <= allowed
    )


class _Zygote:
    """The caller's end: a SOCK_SEQPACKET pair, one request (and one pid back) per fork."""

    def __init__(self) -> None:
        self.owner = os.getpid()
        self.lock = threading.Lock()
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.control = ours
        self.process = subprocess.Popen(
            [sys.executable, "-m", "simbridge.zygote", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
        )
        theirs.close()
        atexit.register(self.close)

    def fork(self, request: dict[str, Any], fds: tuple[int, int, int, int]) -> int:
        with self.lock:
            socket.send_fds(self.control, [json.dumps(request).encode()], list(fds))
            reply = self.control.recv(_PID.size)
        if len(reply) != _PID.size:
            raise OSError("the flight processes' zygote ended")
        return _PID.unpack(reply)[0]

    def close(self) -> None:
        if os.getpid() != self.owner:  # a forked copy of the process that started it
            return
        self.control.close()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.process.wait(timeout=5.0)


class _Reaped:
    """The CPU time of this process's warm children that ended: a fresh interpreter's would
    be in its RUSAGE_CHILDREN."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.cpu_s = 0.0

    def add(self, cpu_s: float) -> None:
        with self.lock:
            self.cpu_s += cpu_s


_reaped = _Reaped()


def reaped_cpu_s() -> float:
    """CPU seconds of the warm children this process has seen end (cf. RUSAGE_CHILDREN)."""
    return _reaped.cpu_s


_zygotes: dict[int, _Zygote] = {}
_zygotes_lock = threading.Lock()


def _zygote() -> _Zygote:
    """This process's zygote (a forked process starts its own)."""
    with _zygotes_lock:
        zygote = _zygotes.get(os.getpid())
        if zygote is None or zygote.process.poll() is not None:
            zygote = _zygotes[os.getpid()] = _Zygote()
        return zygote


class WarmProcess(subprocess.Popen):
    """A Popen whose child the zygote forks; its exit status comes over `_status`."""

    def __init__(
        self, zygote: _Zygote, args: list[str], preload: tuple[str, ...], **options: Any
    ) -> None:
        self._zygote = zygote
        self._preload = preload
        self._status: socket.socket | None = None
        # Popen may be waited for from two threads (`fly` watches its simulator): the socket
        # stays open until the object goes, and one thread at a time reads it
        self._status_lock = threading.Lock()
        self._orphaned = False
        super().__init__(args, **options)

    def _execute_child(  # type: ignore[override]
        self, args: list[str], executable: Any, preexec_fn: Any, close_fds: bool,
        pass_fds: Any, cwd: Any, env: Any, startupinfo: Any, creationflags: int, shell: bool,
        p2cread: int, p2cwrite: int, c2pread: int, c2pwrite: int, errread: int, errwrite: int,
        *rest: Any,
    ) -> None:  # fmt: skip
        process_group = rest[-1] if rest and rest[-1] != -1 else None  # Popen's -1: none
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        request = {
            "argv": list(args),
            "preload": list(self._preload),
            "cwd": os.fsdecode(cwd) if cwd is not None else os.getcwd(),
            "env": {**(os.environ if env is None else env)},
            "process_group": process_group,
        }
        # a stream not redirected is this process's own; where it has none (a multiprocessing
        # worker closes its stdin), the child reads or writes /dev/null
        stand_ins: list[int] = []
        streams = [p2cread, c2pwrite, errwrite]
        for k, fd in enumerate(streams):
            if fd == -1:
                streams[k] = k if _is_open(k) else os.open(os.devnull, os.O_RDWR)
                stand_ins += [streams[k]] if streams[k] != k else []
        try:
            self.pid = self._zygote.fork(request, (*streams, theirs.fileno()))
            ours.setblocking(False)
            self._status = ours
            self._child_created = True
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
            for fd in stand_ins:
                os.close(fd)
            self._close_pipe_fds(p2cread, p2cwrite, c2pread, c2pwrite, errread, errwrite)

    def _read_status(self) -> None:
        """The exit status, if the zygote has sent it; if the zygote ended first (its socket
        closed with nothing sent), whether the pid is gone."""
        assert self._status is not None
        with self._status_lock:
            if self.returncode is not None:
                return
            if not self._orphaned:
                try:
                    data = self._status.recv(_STATUS.size)
                except BlockingIOError:
                    return
                except OSError:
                    data = b""
                if len(data) == _STATUS.size:
                    self.returncode, cpu_s = _STATUS.unpack(data)
                    _reaped.add(cpu_s)
                    return
                self._orphaned = True
            if not _alive(self.pid):
                self.returncode = -signal.SIGKILL

    def _internal_poll(self, *_: Any, **__: Any) -> int | None:  # type: ignore[override]
        if self.returncode is None and self._status is not None:
            self._read_status()
        return self.returncode

    def _wait(self, timeout: float | None) -> int:  # type: ignore[override]
        assert self._status is not None
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            self._read_status()
            if self.returncode is not None:
                return self.returncode
            left = None if end is None else end - time.monotonic()
            if left is not None and left <= 0:
                raise subprocess.TimeoutExpired(self.args, timeout)  # type: ignore[arg-type]
            if self._orphaned:  # watch the pid
                time.sleep(0.05 if left is None else min(0.05, left))
            else:
                select.select([self._status], [], [], left)

    def __del__(self) -> None:
        # one still running is kept by Popen (subprocess._active) and polled on
        if self._status is not None and self.returncode is not None:
            self._status.close()
        super().__del__()


def _is_open(fd: int) -> bool:
    try:
        os.fstat(fd)
    except OSError:
        return False
    return True


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


# --- the zygote's side --------------------------------------------------------------------


def serve(control: socket.socket) -> list[str] | None:
    """Fork a child per request until the caller closes `control`. Returns in a child (its
    command's arguments after the interpreter's: `-m MODULE ...`), and None in the zygote
    when it is done."""
    # a terminal's Ctrl-C reaches the whole process group: the children act on it, and the
    # zygote ends when its caller does
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    wake_read, wake_write = os.pipe()
    os.set_blocking(wake_write, False)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    signal.set_wakeup_fd(wake_write)
    children: dict[int, socket.socket] = {}
    python_env = {k: v for k, v in os.environ.items() if k.startswith("PYTHON")}
    while True:
        ready, _, _ = select.select([control, wake_read], [], [])
        if wake_read in ready:
            os.read(wake_read, 4096)
        _reap(children)
        if control not in ready:
            continue
        message, fds, _, _ = socket.recv_fds(control, _MAX_REQUEST, 4)
        if not message:
            return None
        request = json.loads(message)
        for name in request["preload"]:
            # one that fails to import fails in the child, which reports it as it would
            with contextlib.suppress(Exception):
                importlib.import_module(name)
        pid = os.fork()
        if pid == 0:
            os.close(wake_read)
            os.close(wake_write)
            control.close()  # through its object, which would otherwise close it again
            for status in children.values():
                status.close()
            return _become(request, fds, python_env)
        for fd in fds[:3]:
            os.close(fd)
        children[pid] = socket.socket(fileno=fds[3])
        control.send(_PID.pack(pid))


def _reap(children: dict[int, socket.socket]) -> None:
    while children:
        try:
            pid, status, usage = os.wait4(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        sock = children.pop(pid, None)
        if sock is not None:
            cpu_s = usage.ru_utime + usage.ru_stime
            with contextlib.suppress(OSError):
                sock.send(_STATUS.pack(os.waitstatus_to_exitcode(status), cpu_s))
            sock.close()


def _become(request: dict[str, Any], fds: list[int], python_env: dict[str, str]) -> list[str]:
    """In the child: the process `python -m MODULE ARGS` would be, or exec it as asked where
    the interpreter's own settings differ from the zygote's."""
    signal.set_wakeup_fd(-1)
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    os.close(fds[3])
    if request["process_group"] is not None:
        os.setpgid(0, request["process_group"])
    for target, fd in enumerate(fds[:3]):
        os.dup2(fd, target)
    for fd in set(fds[:3]):
        if fd > 2:
            os.close(fd)
    os.chdir(request["cwd"])
    sys.path[0] = request["cwd"]  # as `python -m` puts its folder first
    env: dict[str, str] = request["env"]
    argv: list[str] = request["argv"]
    if {k: v for k, v in env.items() if k.startswith("PYTHON")} != python_env:
        os.execve(argv[0], argv, env)
    os.environ.clear()
    os.environ.update(env)
    # `ps` and /proc show the command, not the zygote's
    setproctitle.setproctitle(" ".join(argv))
    # the streams Python opens at start, on the child's descriptors (the zygote's own stay
    # referenced by sys.__stdout__ and the like: collected, they would close 0, 1 and 2)
    sys.stdin = open(0, closefd=False)  # noqa: SIM115 (the process's own, never closed)
    sys.stdout = open(1, "w", buffering=1 if os.isatty(1) else -1, closefd=False)  # noqa: SIM115
    sys.stderr = open(2, "w", buffering=1, errors="backslashreplace", closefd=False)  # noqa: SIM115
    if env.get("PYTHONUNBUFFERED"):
        sys.stdout.reconfigure(write_through=True)
        sys.stderr.reconfigure(write_through=True)
    return argv[1:]


def _main() -> None:
    # the title's room is the zygote's arguments and environment: claimed before a child
    # replaces the environment
    setproctitle.setproctitle(setproctitle.getproctitle())
    args = serve(socket.socket(fileno=int(sys.argv[1])))
    if args is not None:  # a child: `-m MODULE ARGS`, as the interpreter runs it
        sys.argv = [sys.argv[0], *args[2:]]
        runpy.run_module(args[1], run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    _main()
