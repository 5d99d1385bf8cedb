"""The docs agree with the code and with each other, where a machine can tell: every flag of
a `skyhelm` command they show exists in its parser, every `make` target they name exists,
a shell line never calls a bare `skyhelm` (not on the PATH after `make run`), every fleet
server they start shares the tokens, the curl sessions find the vehicle and give the lease
back, and the figures they quote (`make bench`'s duration, the lease's defaults) are the
measured and configured ones."""

from __future__ import annotations

import argparse
import functools
import json
import re
import shlex
from pathlib import Path

import pytest

from bench.run_all import BUDGET_S
from server.cli import build_parser
from server.settings import Settings
from sim.process.cli import build_parser as build_sim_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = [README, *sorted((ROOT / "docs").glob("*.md"))]
FENCED = re.compile(r"^\s*```[\w-]*\n(.*?)^\s*```", re.MULTILINE | re.DOTALL)
INLINE = re.compile(r"`([^`\n]+)`")
SKYHELM = re.compile(r"(?:^|(?<=[\s(`]))(?:\.venv/bin/)?skyhelm (serve|sim|replay|router)\b")
MAKE_TARGET = re.compile(r"\bmake ([a-z][a-z0-9-]*)")
MINUTES = re.compile(r"~(\d+) min on 2 cores")


def _blocks(doc: Path) -> list[str]:
    return [block for block in FENCED.findall(doc.read_text())]


def _inline(doc: Path) -> list[str]:
    return INLINE.findall(FENCED.sub("", doc.read_text()))


def _code(doc: Path) -> list[str]:
    """Every command-like piece of the doc: its code blocks' lines (continuations joined)
    and its inline code."""
    lines = []
    for block in _blocks(doc):
        lines += block.replace("\\\n", " ").splitlines()
    return lines + _inline(doc)


def _commands(text: str) -> list[tuple[str, list[str]]]:
    """Each `skyhelm SUB ...` in a line of code, with the words that follow it."""
    found = []
    for match in SKYHELM.finditer(text):
        rest = re.split(r"[#|;`]|&&", text[match.end() :], maxsplit=1)[0]
        try:
            words = shlex.split(rest)
        except ValueError:
            words = rest.split()
        found.append((match.group(1), words))
    return found


@functools.cache
def _options(sub: str) -> frozenset[str]:
    if sub == "sim":
        parser = build_sim_parser()
    else:
        subparsers = next(
            action
            for action in build_parser()._actions
            if isinstance(action, argparse._SubParsersAction)
        )
        parser = subparsers.choices[sub]
    return frozenset(option for action in parser._actions for option in action.option_strings)


def _flags(words: list[str]) -> list[str]:
    return [word.split("=", 1)[0] for word in words if word.startswith("--")]


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_every_skyhelm_flag_in_the_docs_exists(doc: Path) -> None:
    unknown = [
        (sub, flag)
        for line in _code(doc)
        for sub, words in _commands(line)
        for flag in _flags(words)
        if flag not in _options(sub)
    ]
    assert unknown == []


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_every_make_target_in_the_docs_exists(doc: Path) -> None:
    targets = set(re.findall(r"^([a-z][a-z0-9-]*):", (ROOT / "Makefile").read_text(), re.M))
    named = {target for line in _code(doc) for target in MAKE_TARGET.findall(line)}
    assert named - targets == set()


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_no_shell_line_runs_a_bare_skyhelm(doc: Path) -> None:
    """`make run` installs into .venv: `skyhelm` is .venv/bin/skyhelm there."""
    bare = [
        line
        for block in _blocks(doc)
        for line in block.splitlines()
        if line.lstrip().startswith("skyhelm ")
    ]
    assert bare == []


def test_every_fleet_server_in_the_docs_shares_the_token() -> None:
    servers = [
        words
        for doc in DOCS
        for block in _blocks(doc)
        for line in block.replace("\\\n", " ").splitlines()
        for sub, words in _commands(line)
        if sub == "serve" and {"--zenoh", "--fleet"} & set(words)
    ]
    assert len(servers) >= 5
    assert [words for words in servers if "--token" not in words] == []


def test_make_bench_takes_what_the_docs_say() -> None:
    quoted = {
        path.name: [int(m) for m in MINUTES.findall(path.read_text())]
        for path in (README, ROOT / "Makefile", ROOT / "bench" / "run_all.py")
    }
    minutes = {m for found in quoted.values() for m in found}
    assert all(quoted.values()), quoted
    assert len(minutes) == 1, quoted  # one figure everywhere
    (said,) = minutes
    measured_s = json.loads((ROOT / "bench" / "results" / "run_all.json").read_text())[
        "total_seconds"
    ]
    assert abs(said - measured_s / 60) <= 1.0, (said, measured_s)
    assert said * 60 <= BUDGET_S


@pytest.mark.parametrize("doc", [README, ROOT / "docs" / "api.md"], ids=lambda p: p.name)
def test_the_curl_sessions_find_the_vehicle_and_give_the_lease_back(doc: Path) -> None:
    (session,) = [block for block in _blocks(doc) if "URL='" in block]
    assert "/vehicles/1" not in session  # the id comes from GET /vehicles
    assert re.search(r"^V=\$\(.*\$API/vehicles ", session, re.M)
    assert re.search(r"^trap '.*-X DELETE \$API/vehicles/\$V/control' EXIT$", session, re.M)
    assert "2>/dev/null" not in session  # HTTP errors show


def test_the_lease_figures_in_the_readme_are_the_defaults() -> None:
    fields = Settings.model_fields
    text = README.read_text()
    ttl_s = fields["lease_ttl_s"].default
    low_s, high_s = fields["lease_ttl_min_s"].default, fields["lease_ttl_max_s"].default
    deadman_s = fields["deadman_timeout_s"].default
    assert f"The control lease lasts {ttl_s:g} s" in text
    assert f"within {low_s:g}..{high_s:g} s" in text
    assert f"`deadman_timeout_s` ({deadman_s:g} s" in text


def test_the_readme_and_api_md_have_one_curl_session_that_flies_from_where_it_starts() -> None:
    readme, api = (
        next(block for block in _blocks(doc) if "URL='" in block)
        for doc in (README, ROOT / "docs" / "api.md")
    )
    assert readme == api
    # the leg is measured from where it starts, not from position_ned's origin
    assert re.search(r"^N0=\$\(state .*north_m", readme, re.M)
    assert "north_m'] > $N0 + 10" in readme
    assert '"north_m": 0, "east_m": 0, "down_m": -5' not in readme  # no flight to the origin


def test_position_ned_says_what_it_is_measured_from() -> None:
    from skyhelm_wire.state import VehicleStateOut

    described = VehicleStateOut.model_fields["position_ned"].description or ""
    assert "estimator's local origin" in described
    assert "not of home or of where a flight started" in described
    assert "**`position_ned` is measured from the estimator's local origin**" in (
        ROOT / "docs" / "api.md"
    ).read_text()
