"""PyBullet, imported without its build banner: the C extension prints "pybullet build time:
..." on stderr when it loads, which is not our output (every command showed it). Only the
import is silenced; everything PyBullet says later reaches stderr as before."""

from __future__ import annotations

import os
from types import ModuleType


def _import_quietly() -> ModuleType:
    try:
        saved = os.dup(2)
    except OSError:  # no stderr descriptor to silence (an embedding host): a plain import
        import pybullet

        return pybullet
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            import pybullet
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    return pybullet


pybullet = _import_quietly()
