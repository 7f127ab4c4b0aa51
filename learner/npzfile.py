"""Self-describing `.npz` files (arrays plus a JSON header), read with clear errors."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from simbridge.config import ConfigError

T = TypeVar("T")


def read_npz(
    path: Path, fmt: str, version: int, kind: str, read: Callable[[dict[str, Any], Any], T]
) -> T:
    """`read(header, arrays)` on a file whose header says `fmt` and `version`; a missing,
    damaged or foreign file stops with one message naming it."""
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if header.get("format") != fmt:
                raise ConfigError(f"{path}: not a groundfx {kind}")
            if header.get("version") != version:
                raise ConfigError(
                    f"{path}: {kind} version {header.get('version')}, "
                    f"this groundfx reads version {version}"
                )
            return read(header, data)
    except ConfigError:
        raise
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except Exception as err:  # zip, JSON, missing or malformed arrays
        raise ConfigError(
            f"{path}: not a readable groundfx {kind} ({type(err).__name__})"
        ) from None
