"""The layout is the architecture: imports go down the packages (mission -> autopilot ->
learner -> simbridge) and no modules import each other in a circle."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("simbridge", "learner", "autopilot", "mission")  # each may import those before it


def _modules() -> dict[str, set[str]]:
    """Every module of the four packages and the modules of ours it imports (anywhere in it,
    function-level imports included)."""
    files = [p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")]
    names = {}
    for p in files:
        parts = p.relative_to(ROOT).with_suffix("").parts
        names[p] = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
    known = set(names.values())
    imports: dict[str, set[str]] = {}
    for path, name in names.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            found |= {t for t in targets if t in known and t != name}
        imports[name] = found
    return imports


def test_imports_go_down_the_packages() -> None:
    upward = [
        f"{m} imports {d}"
        for m, deps in _modules().items()
        for d in deps
        if PACKAGES.index(d.split(".")[0]) > PACKAGES.index(m.split(".")[0])
    ]
    assert upward == []


def test_no_modules_import_each_other_in_a_circle() -> None:
    imports = _modules()
    # a package's __init__ is imported with any of its modules: not an edge of its own
    graph = {m: {d for d in deps if not _is_parent(d, m)} for m, deps in imports.items()}
    circles = []
    for start in graph:
        stack, seen = [(start, (start,))], set()
        while stack:
            node, path = stack.pop()
            for nxt in graph.get(node, ()):
                if nxt == start:
                    circles.append(" -> ".join((*path, start)))
                elif nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, (*path, nxt)))
    assert circles == []


def _is_parent(package: str, module: str) -> bool:
    return module.startswith(package + ".")


# The autopilot's rooms, lowest first: a room imports only from its own and lower levels.
AUTOPILOT_LEVELS = (
    {"types", "identity", "metrics"},  # what every room passes around; pure figures
    {"simlink", "estimation", "control"},  # the simulator link; state estimation; control laws
    {"commander"},  # phases, modes, requests, failsafes, mission items
    {"params"},  # the parameters of every room, tuned over MAVLink
    {"gcs", "recording", "online", "nav_metrics", "truth"},  # the loop's companions
    {"summary", "tuning", "request", "flight_config"},  # the request; settings; figures
    {"runner"},  # thin wiring: link -> estimate -> command -> control -> send
)


def _room(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "autopilot" and len(parts) > 1 else None


def test_autopilot_rooms_import_down_their_levels() -> None:
    level = {room: i for i, rooms in enumerate(AUTOPILOT_LEVELS) for room in rooms}
    found = {_room(m) for m in _modules()} - {None}
    assert found <= set(level), f"rooms without a level: {sorted(found - set(level))}"
    upward = [
        f"{m} imports {d}"
        for m, deps in _modules().items()
        for d in deps
        if _room(m) and _room(d) and level[_room(d)] > level[_room(m)]
    ]
    assert upward == []


MAX_MODULE_LINES = 500  # a module longer than this holds more than one concern
MAX_FUNCTION_LINES = 80  # a function longer than this holds more than one step
SIZED_PACKAGES = ("autopilot", "simbridge")


def _sized_files() -> list[Path]:
    return sorted(p for pkg in SIZED_PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def test_no_module_is_over_its_size() -> None:
    long = [
        f"{p.relative_to(ROOT)}: {n} lines"
        for p in _sized_files()
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    ]
    assert long == []


def test_no_function_is_over_its_size() -> None:
    long = []
    for p in _sized_files():
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                assert node.end_lineno is not None
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{p.relative_to(ROOT)}:{node.lineno} {node.name}: {lines} lines")
    assert long == []
