"""How often a refusal is explained: a stream of bad requests (setpoints at 50 Hz, a script
setting a thousand misspelt parameters) gets one STATUSTEXT per kind of refusal per
`REPEAT_S`, not one per message; every refused message is still counted on the link."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

REPEAT_S = 5.0  # wall seconds before a refusal of the same kind is explained again
MAX_KINDS = 64  # hostile input naming ever new kinds: the memory stays bounded all the same


@dataclass
class RefusalLimiter:
    said_wall_s: dict[str, float] = field(default_factory=dict)  # kind -> when last explained

    def due(self, kind: str, wall_s: float) -> bool:
        """Whether a refusal of `kind` is to be explained now (and, if so, noted as said)."""
        if wall_s - self.said_wall_s.get(kind, -math.inf) <= REPEAT_S:
            return False
        if len(self.said_wall_s) >= MAX_KINDS:
            self.said_wall_s.clear()
        self.said_wall_s[kind] = wall_s
        return True
