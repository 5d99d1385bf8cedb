"""Small markdown helpers for the benchmarks' report() sections."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A markdown table; floats keep the precision they were formatted with by the caller."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def ratio(numerator: float, denominator: float) -> str:
    """``numerator / denominator`` as "0.48×", or "n/a" when it cannot be formed."""
    if not denominator:
        return "n/a"
    return f"{numerator / denominator:.2f}×"
