"""What a benchmark contributes to docs/PERFORMANCE.md (written by ``python -m bench.report``,
the last step of ``make bench``).

A benchmark module may define ``report(result) -> Section | None``: ``result`` is what it
wrote to bench/results/<name>.json. The section's figures are matplotlib PNGs saved with
``save_figure`` into docs/img/perf/. Claims are ratios measured in one run; every figure
names the machine it ran on (``machine_caption``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.figure import Figure as MplFigure

DOCS_DIR = Path(__file__).resolve().parent.parent / "docs"
FIGURE_DIR = DOCS_DIR / "img" / "perf"
# Where save_figure writes: docs/ unless bench.report renders elsewhere (output_to).
_docs_dir = [DOCS_DIR]


@contextlib.contextmanager
def output_to(docs_dir: Path) -> Iterator[None]:
    """Save figures under ``docs_dir``/img/perf while the block runs."""
    _docs_dir.append(docs_dir)
    try:
        yield
    finally:
        _docs_dir.pop()


@dataclass(frozen=True)
class Figure:
    path: str  # relative to docs/
    caption: str


@dataclass
class Section:
    title: str
    # lower comes first in the document
    order: int
    markdown: str
    figures: list[Figure] = field(default_factory=list)


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display), imported only when a report is
    drawn, so a benchmark runs without matplotlib."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def machine_caption(machine: dict[str, Any]) -> str:
    """One line naming the machine a figure comes from."""
    load = machine.get("load_average_before") or machine.get("load_average_after")
    load_text = f", load {load[0]:.2f}" if load else ""
    return (
        f"{machine.get('cpus', '?')} CPUs, {machine.get('platform', '?')}, "
        f"Python {machine.get('python', '?')}{load_text}"
    )


def save_figure(fig: MplFigure, name: str, caption: str, machine: dict[str, Any]) -> Figure:
    """Save ``fig`` as docs/img/perf/<name>.png with the machine in its footer."""
    docs_dir = _docs_dir[-1]
    figure_dir = docs_dir / FIGURE_DIR.relative_to(DOCS_DIR)
    figure_dir.mkdir(parents=True, exist_ok=True)
    # below the axes' labels; bbox_inches="tight" takes it in
    fig.text(0.99, -0.02, machine_caption(machine), ha="right", va="top",
             fontsize=7, color="#666666")
    path = figure_dir / f"{name}.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return Figure(path=path.relative_to(docs_dir).as_posix(), caption=caption)
