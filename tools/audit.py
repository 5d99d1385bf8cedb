"""`make audit`: pip-audit over the packages installed in the project's environment.

Outcomes, each said in one clear line (and the exit code):
- vulnerabilities found: they are listed, exit 1;
- audited, none found: "pip-audit: N packages audited, no known vulnerabilities", exit 0;
- the vulnerability service could not be reached (no network, DNS, a proxy), or answered for
  none of the packages (a mirror without PyPI's JSON API says "not found on PyPI" for every
  one — pip-audit itself then reports "No known vulnerabilities found"): a banner saying
  the dependencies were NOT audited and why; exit 0 so an offline `make test` still runs, but
  exit 3 with AUDIT_STRICT=1 (CI sets it: there an unaudited build must fail).
Packages the service does not know (a few private or renamed ones) are listed, not fatal.

    python -m tools.audit [--strict] [pip-audit options...]
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

EXIT_OK = 0
EXIT_VULNERABLE = 1
EXIT_UNAUDITED = 3
# What pip-audit's output says when the service is out of reach.
_UNREACHABLE_SIGNS = (
    "ConnectionError",
    "NameResolutionError",
    "Max retries exceeded",
    "Failed to resolve",
    "Temporary failure in name resolution",
    "timed out",
    "ProxyError",
    "SSLError",
)


@dataclass
class Report:
    audited: list[str] = field(default_factory=list)
    vulnerable: list[str] = field(default_factory=list)  # "name version: ID (fix: x)"
    unknown: list[str] = field(default_factory=list)  # not found by the service
    unreachable: str | None = None  # why nothing could be audited


def classify(returncode: int, output_json: str | None, stderr: str) -> Report:
    """What one pip-audit run found, from its JSON output and its stderr."""
    report = Report()
    data: dict[str, Any] | None = None
    if output_json:
        try:
            data = json.loads(output_json)
        except ValueError:
            data = None
    if data is None:
        signs = [sign for sign in _UNREACHABLE_SIGNS if sign in stderr]
        last = stderr.strip().splitlines()[-1:] or [f"pip-audit exited {returncode}"]
        report.unreachable = f"{', '.join(signs) or 'no report'}: {last[0][:300]}"
        return report
    for dependency in data.get("dependencies", []):
        name = f"{dependency.get('name')} {dependency.get('version', '')}".strip()
        reason = dependency.get("skip_reason")
        if reason:
            if "editable" not in reason:
                report.unknown.append(f"{name}: {reason}")
            continue
        report.audited.append(name)
        for vuln in dependency.get("vulns", []):
            fixes = ", ".join(vuln.get("fix_versions", [])) or "none yet"
            report.vulnerable.append(f"{name}: {vuln.get('id')} (fixed in {fixes})")
    if not report.audited and report.unknown:
        report.unreachable = (
            f"the service answered for none of the {len(report.unknown)} packages "
            f"(first: {report.unknown[0]})"
        )
    return report


def verdict(report: Report, strict: bool) -> tuple[int, list[str]]:
    """The exit code and the lines to print."""
    if report.vulnerable:
        return EXIT_VULNERABLE, [
            f"pip-audit: {len(report.vulnerable)} known vulnerabilities:",
            *(f"  {line}" for line in report.vulnerable),
        ]
    if report.unreachable is not None:
        banner = "=" * 78
        action = "failing (AUDIT_STRICT=1)" if strict else "continuing (AUDIT_STRICT=1 fails)"
        return (EXIT_UNAUDITED if strict else EXIT_OK), [
            banner,
            "pip-audit: the dependencies were NOT audited: the vulnerability service could not",
            f"be reached or did not answer ({report.unreachable}); {action}.",
            banner,
        ]
    lines = [f"pip-audit: {len(report.audited)} packages audited, no known vulnerabilities"]
    if report.unknown:
        lines.append(f"  not known to the service ({len(report.unknown)}):")
        lines += [f"    {line}" for line in report.unknown]
    return EXIT_OK, lines


def run(extra: Sequence[str], python: str = sys.executable) -> Report:
    with tempfile.TemporaryDirectory(prefix="skyhelm-audit-") as tmp:
        out = Path(tmp) / "audit.json"
        command = [
            python, "-m", "pip_audit", "--skip-editable", "--progress-spinner", "off",
            "--format", "json", "--output", str(out), *extra,
        ]
        done = subprocess.run(command, capture_output=True, text=True, timeout=600, check=False)
        text = out.read_text() if out.exists() and out.stat().st_size else None
        return classify(done.returncode, text, done.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    strict = os.environ.get("AUDIT_STRICT", "") not in ("", "0")
    if "--strict" in args:
        args.remove("--strict")
        strict = True
    code, lines = verdict(run(args), strict)
    print("\n".join(lines), file=sys.stderr if code else sys.stdout, flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
