"""The campaign runner every campaign command shares: tasks (a seeded flight, a bench case)
run by a local process pool (`--workers K`) or as Ray tasks (`--ray ADDRESS`), each result
appended to the campaign's results file as it finishes, so that a campaign that stopped
resumes where it stopped, and a progress bar with its ETA.

A task is a top-level function and its arguments, named by an id; its key is what decides its
result (a changed definition is a new task, flown again). The same task gives the same
result wherever it runs: the flights are lockstep and seeded. A task whose worker dies (a
killed process, a lost node) is run again once, elsewhere. On a Ray cluster a task carries
the files its arguments name, and what it writes under its outputs comes back and is written
on the machine that started the campaign (`shipping`).
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import get_context
from multiprocessing.context import BaseContext
from pathlib import Path
from typing import Any

from tqdm import tqdm

from mission.campaigns.shipping import input_files, land, run_carried
from simbridge.config import ConfigError
from simbridge.zygote import reaped_cpu_s


@dataclass(frozen=True)
class Task:
    id: str  # unique within a campaign: the results file's key
    key: str  # what decides the result: a task whose key changed is run again
    fn: Callable[..., dict[str, Any]]  # top level (a worker imports it by name)
    args: tuple[Any, ...] = ()
    # where it runs on a cluster: the files and folders it writes (brought back to where the
    # campaign started) and the folders it reads beyond the files its arguments name
    outputs: tuple[str | Path, ...] = ()
    input_folders: tuple[str | Path, ...] = ()
    # modules its function imports when it runs: on a local pool, imported once by the fork
    # server the workers start from, not by every worker
    imports: tuple[str, ...] = ()


PACKAGES = ("autopilot", "simbridge", "learner", "mission")


def source_fingerprint() -> str:
    """A hash of groundfx's source: part of a task's key where a result depends on the code
    (a bench rerun after a change runs again; a resumed one does not)."""
    root = Path(__file__).resolve().parents[2]
    digest = hashlib.sha256()
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            digest.update(path.relative_to(root).as_posix().encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def load_results(path: Path) -> dict[str, dict[str, Any]]:
    """Finished tasks by id. A torn last line (the campaign was killed while writing) and
    failed tasks are left out: they are run again."""
    results: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return results
    for line in path.read_text().splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(record, dict) and "id" in record and "error" not in record:
            results[record["id"]] = record
    return results


def append_result(path: Path, record: dict[str, Any]) -> None:
    """One line per task, on disk before the next is counted; after a torn last line (a
    campaign killed while writing) on a line of its own."""
    torn = False
    if path.exists() and path.stat().st_size > 0:
        with path.open("rb") as f:
            f.seek(-1, os.SEEK_END)
            torn = f.read(1) != b"\n"
    with path.open("a") as f:
        f.write(("\n" if torn else "") + json.dumps(record) + "\n")
        f.flush()
        os.fsync(f.fileno())


def ray_init(address: str, workers: int | None = None) -> None:
    """Connect to a Ray cluster (`auto`, `HOST:PORT`, `ray://HOST:PORT`), or `local`: start
    a Ray instance on this machine."""
    try:
        import ray
    except ImportError:
        raise ConfigError(
            "--ray: ray is not installed; install the extra: pip install -c constraints.txt "
            "-e '.[ray]'"
        ) from None
    if ray.is_initialized():
        return
    if address == "local":  # a new instance here, even where `ray start` left one running
        ray.init(
            address="local",
            num_cpus=workers or os.cpu_count(),
            include_dashboard=False,
            log_to_driver=False,
        )
    else:
        ray.init(address=address, log_to_driver=False)


def _run(task: Task) -> dict[str, Any]:
    """A task in a worker: its record, or the error that ended it (a figure, not the end of
    the campaign)."""
    cpu_s = _cpu_s()
    try:
        record = task.fn(*task.args)
    except Exception as err:
        record = {"error": f"{type(err).__name__}: {err}"}
    # its own and its processes' (a flight's simulator and autopilot, reaped by then)
    return {**record, "id": task.id, "key": task.key, "cpu_s": _cpu_s() - cpu_s}


def _cpu_s() -> float:
    own, children = (
        resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
    )
    warm = reaped_cpu_s()  # a flight's processes forked by a zygote are not our children
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime + warm


@dataclass(frozen=True)
class Here:
    """What a pool worker takes from the process that submitted its task: a worker forked
    from the fork server would otherwise have the server's, from when it started."""

    cwd: str
    env: dict[str, str]
    # the cores it may run on, where the system says (Linux); `bench campaign` holds a pool
    # to one
    cpus: frozenset[int] | None

    @staticmethod
    def now() -> Here:
        cpus = frozenset(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
        return Here(os.getcwd(), dict(os.environ), cpus)


def _run_here(task: Task, here: Here) -> dict[str, Any]:
    os.chdir(here.cwd)
    if os.environ != here.env:
        os.environ.clear()
        os.environ.update(here.env)
    if here.cpus is not None:
        os.sched_setaffinity(0, here.cpus)
    return _run(task)


def _pool_context(tasks: list[Task]) -> BaseContext:
    """Workers forked from a fork server: a fresh interpreter of its own, with no threads or
    sockets of this process, that has imported the tasks' modules (torch, scipy, rerun for a
    diagnosis) once; each worker starts from it in milliseconds, not seconds."""
    context = get_context("forkserver")
    # takes effect when the server starts: at this process's first pool
    modules = {__name__} | {t.fn.__module__ for t in tasks} | {m for t in tasks for m in t.imports}
    context.set_forkserver_preload(sorted(modules))
    return context


def _pool(tasks: list[Task], workers: int) -> Iterator[dict[str, Any]]:
    """Tasks on a local pool; the tasks of a pool whose worker died go to a fresh pool once."""
    left, retried = {t.id: t for t in tasks}, False
    here = Here.now()
    while left:
        with ProcessPoolExecutor(workers, mp_context=_pool_context(tasks)) as pool:
            pending = {pool.submit(_run_here, t, here): t.id for t in left.values()}
            try:
                while pending:
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        task_id = pending.pop(future)
                        record = future.result()
                        del left[task_id]
                        yield record
            except BrokenProcessPool:
                if retried:
                    for task_id in left:
                        yield {"id": task_id, "key": "", "error": "its worker process died twice"}
                    return
                retried = True
            finally:
                for future in pending:
                    future.cancel()


def _run_carried(task: Task, files: dict[str, bytes]) -> dict[str, Any]:
    return run_carried(_run, task, files)


def _ray(tasks: list[Task]) -> Iterator[dict[str, Any]]:
    import ray

    # one task per core, as the pool; a task whose worker or node dies is run again once.
    # Its files go with it and come back in its record: a cluster's machines share no disk.
    remote = ray.remote(num_cpus=1, max_retries=1)(_run_carried)
    pending = [
        remote.remote(t, input_files(t.args, tuple(Path(f) for f in t.input_folders)))
        for t in tasks
    ]
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield ray.get(ref)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


def run_tasks(
    tasks: list[Task],
    results_path: Path,
    workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
    desc: str = "campaign",
    on_record: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, dict[str, Any]]:
    """Run the tasks the results file lacks (or holds under another key); returns every
    finished task's record by id, failed ones included (`error`). `on_record`: called on
    each record as it lands, before the bar moves."""
    results_path.parent.mkdir(parents=True, exist_ok=True)
    kept = load_results(results_path)
    # a record without a key is from before keys were written: its id alone decides
    done = {
        t.id: kept[t.id] for t in tasks if t.id in kept and kept[t.id].get("key", t.key) == t.key
    }
    todo = [t for t in tasks if t.id not in done]
    workers = workers or os.cpu_count() or 1
    if ray_address is not None:
        ray_init(ray_address, workers)
        stream = _ray(todo)
    else:
        stream = _pool(todo, min(workers, max(len(todo), 1)))
    bar = tqdm(total=len(tasks), initial=len(done), unit="task", desc=desc, disable=not progress)
    failed = 0
    try:
        for record in stream:
            land(record)  # a Ray task's files, written here
            append_result(results_path, record)
            if "error" in record:
                failed += 1
                tqdm.write(f"{desc}: {record['id']} failed: {record['error']}")
            if on_record is not None:
                on_record(record)
            done[record["id"]] = record
            bar.update(1)
            bar.set_postfix(failed=failed)
    finally:
        bar.close()
    return done
