"""A file generated from the wire models: written, or checked to be current."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path


def write_or_check(
    argv: list[str] | None, doc: str | None, out: Path, generate: Callable[[], str], command: str
) -> int:
    """`command` writes `out` from `generate()`; with --check it only exits 1 when `out` is
    not what `generate()` gives."""
    parser = argparse.ArgumentParser(description=(doc or "").splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check that it is current")
    args = parser.parse_args(argv)
    text = generate()
    if args.check:
        current = out.exists() and out.read_text() == text
        if not current:
            print(f"{out} is not current: run {command}", file=sys.stderr)
        return 0 if current else 1
    out.write_text(text)
    return 0
