"""`groundfx bench soak`: missions flown back to back by MAVSDK against one `groundfx sitl`,
as a ground station left connected for hours would: missions flown, failures, and how the
simulator's and the autopilot's resident memory grow from the first mission to the last."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from simbridge.config import ConfigError

SQUARE_PLAN = Path(__file__).resolve().parents[1] / "examples" / "square.plan"
MISSION_WALL_S = 120.0  # one mission's bound, not a wait: at most this long before a failure
CONNECT_WALL_S = 60.0  # the first heartbeat (a loaded machine takes a while to start)


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def resident_kib(pid: int) -> int:
    """A process's resident memory (VmRSS), KiB; 0 once it has gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def children(pid: int) -> list[int]:
    """The process's children (Linux), in the order they were started."""
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(p) for p in text.split()]


def _command_line(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


async def _within(what: str, seconds: float, awaitable: Awaitable[Any]) -> Any:
    try:
        return await asyncio.wait_for(awaitable, seconds)
    except TimeoutError:
        raise RuntimeError(f"{what}: nothing within {seconds:g} s") from None


async def _until(stream: Any, ok: Callable[[Any], bool]) -> Any:
    async with contextlib.aclosing(stream) as values:
        async for value in values:
            if ok(value):
                return value
    raise RuntimeError("the subscription ended")


async def _fly_one(raw: Any, action: Any, telemetry: Any, items: list[Any]) -> None:
    """Upload, arm, start, and wait for the landing's disarm."""
    await _within("mission upload", 20, raw.upload_mission(items))
    armed_then_disarmed = asyncio.create_task(
        _until(telemetry.subscribe_armed(), _after(bool, lambda armed: not armed))
    )
    try:
        await asyncio.sleep(0)  # subscribed before the arm
        await _within("arm", 10, action.arm())
        await _within("mission start", 10, raw.start_mission())
        await _within("the landing's disarm", MISSION_WALL_S, armed_then_disarmed)
    finally:
        armed_then_disarmed.cancel()
        await asyncio.gather(armed_then_disarmed, return_exceptions=True)


def _after(before: Callable[[Any], bool], then: Callable[[Any], bool]) -> Callable[[Any], bool]:
    seen: list[Any] = []

    def ok(value: Any) -> bool:
        if before(value):
            seen.append(value)
        return bool(seen) and then(value)

    return ok


async def _soak(
    port: int,
    missions: int,
    pids: Callable[[], dict[str, int]],
    ended: Callable[[], int | None],
    say: Callable[[str], None],
) -> dict[str, Any]:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    flown, failures, memory = 0, [], []
    async with Mavsdk(config) as sdk:
        await _within("connect", 10, sdk.add_any_connection(f"udpout://127.0.0.1:{port}"))
        system = await _within(
            "discovery", CONNECT_WALL_S, sdk.first_autopilot(timeout_s=CONNECT_WALL_S)
        )
        raw, action, telemetry = (
            MissionRawAsync(system),
            ActionAsync(system),
            TelemetryAsync(system),
        )
        try:
            imported = await _within(
                "import", 10, raw.import_qgroundcontrol_mission(str(SQUARE_PLAN))
            )
            await _within(
                "health",
                CONNECT_WALL_S,
                _until(telemetry.subscribe_health(), lambda h: h.is_armable),
            )
            for n in range(1, missions + 1):
                if ended() is not None:  # nothing more can fly: say so, once
                    failures.append(f"mission {n}: the sitl had ended (exit code {ended()})")
                    say(failures[-1])
                    break
                t0 = time.monotonic()
                try:
                    await _fly_one(raw, action, telemetry, imported.mission_items)
                    flown += 1
                    outcome = "flown"
                except Exception as e:  # a failure is counted and said; the soak goes on
                    failures.append(f"mission {n}: {e}")
                    outcome = f"FAILED: {e}"
                memory.append({name: resident_kib(pid) for name, pid in pids().items()})
                say(
                    f"mission {n}/{missions}: {outcome} in {time.monotonic() - t0:.1f} s; "
                    + ", ".join(f"{k} {v / 1024:.1f} MiB" for k, v in memory[-1].items())
                )
        finally:
            for plugin in (raw, action, telemetry):
                plugin.destroy()
    return {"flown": flown, "failures": failures, "memory_kib": memory}


def soak(
    missions: int,
    identity: str = "px4",
    speedup: str = "max",
    record: Path | None = None,
    say: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Fly `missions` square missions through MAVSDK against one `groundfx sitl` (recording
    to `record`, else not at all); the figures."""
    if missions < 2:
        raise ConfigError(f"--missions: {missions}: at least 2 (growth is measured from the first)")
    try:
        import mavsdk  # noqa: F401
    except ImportError:
        raise ConfigError("bench soak flies with MAVSDK: pip install 'groundfx[dev]'") from None
    port = _free_udp_port()
    sitl = subprocess.Popen(
        [
            *(sys.executable, "-m", "mission.cli", "sitl", "--speedup", speedup),
            *("--identity", identity, "--params-file", "none"),
            *(("--record", str(record)) if record else ("--no-record",)),
            *("--out", f"udpin:127.0.0.1:{port}"),
        ],
        stdout=subprocess.DEVNULL,
        start_new_session=True,
    )

    def pids() -> dict[str, int]:
        named = {}
        for pid in children(sitl.pid):
            line = _command_line(pid)
            named["autopilot" if " autopilot " in f"{line} " else "simulator"] = pid
        return named

    t0 = time.monotonic()
    try:
        result = asyncio.run(_soak(port, missions, pids, sitl.poll, say))
    finally:
        sitl.send_signal(signal.SIGINT)
        try:
            sitl.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(sitl.pid, signal.SIGKILL)
            sitl.wait()
    memory = result.pop("memory_kib")
    growth = {}
    for name in memory[0] if memory else {}:
        first, last = memory[0][name], memory[-1].get(name, 0)
        growth[name] = {
            "first_mib": round(first / 1024, 1),
            "last_mib": round(last / 1024, 1),
            "max_mib": round(max(m.get(name, 0) for m in memory) / 1024, 1),
            "growth_percent": round(100.0 * (last - first) / first, 1) if first else None,
        }
    load = os.getloadavg()[0]
    return {
        "missions": missions,
        **result,
        "memory_after_mission_1_to_last": growth,
        "wall_s": round(time.monotonic() - t0, 1),
        "identity": identity,
        "recording": str(record) if record else None,
        "load_average": round(load, 2),
    }
