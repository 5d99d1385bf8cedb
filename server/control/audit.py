"""The control audit log: every control and deadman event, one JSON object per line in
``<log_dir>/control-audit.jsonl``, so who flew which vehicle when is known after a restart.
The newest entries are also kept in memory for GET /control/audit; at start they are read
back from the file's tail."""

from __future__ import annotations

import json
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

AUDIT_FILE_NAME = "control-audit.jsonl"
AUDIT_MEMORY = 1000  # entries kept in memory (and read back at start)
AUDIT_KINDS = frozenset({"control", "deadman"})


def _finite(value: Any) -> Any:
    """JSON has no NaN: non-finite numbers are written as null, as in every API answer."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {str(key): _finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(item) for item in value]
    return value


class AuditLog:
    def __init__(
        self,
        log_dir: Path | None,
        *,
        memory: int = AUDIT_MEMORY,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        self.path = log_dir / AUDIT_FILE_NAME if log_dir is not None else None
        self._entries: deque[dict[str, Any]] = deque(maxlen=memory)
        # a Unix timestamp is the point of an audit entry, so this is wall-clock time
        self._wall_clock = wall_clock

    def load(self) -> int:
        """Read the file's newest entries back; lines that are not JSON objects are skipped.
        Returns how many were read."""
        if self.path is None or not self.path.is_file():
            return 0
        tail: deque[str] = deque(maxlen=self._entries.maxlen)
        try:
            with self.path.open(encoding="utf-8", errors="replace") as lines:
                tail.extend(lines)
        except OSError as exc:
            log.warning("cannot read the control audit log %s: %s", self.path, exc)
            return 0
        read = 0
        for line in tail:
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(entry, dict):
                self._entries.append(entry)
                read += 1
        return read

    def append(self, vehicle_id: int, kind: str, data: Mapping[str, Any]) -> dict[str, Any]:
        entry = {
            "time_unix_s": round(self._wall_clock(), 3),
            "vehicle": vehicle_id,
            "kind": kind,
            "data": _finite(data),
        }
        self._entries.append(entry)
        if self.path is not None:
            # control events are rare (people taking and giving control), so a small
            # synchronous append on the loop costs less than a writer task would
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                with self.path.open("a", encoding="utf-8") as out:
                    out.write(json.dumps(entry, default=str) + "\n")
            except OSError as exc:
                log.warning("cannot write the control audit log %s: %s", self.path, exc)
        return entry

    def entries(self, vehicle_id: int | None = None, limit: int = 100) -> list[dict[str, Any]]:
        """The newest ``limit`` entries (of one vehicle, or all), oldest first."""
        chosen = [e for e in self._entries if vehicle_id is None or e.get("vehicle") == vehicle_id]
        return chosen[-limit:] if limit > 0 else []
