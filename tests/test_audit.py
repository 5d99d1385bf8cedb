"""`make audit` (tools/audit.py): what a pip-audit run's JSON and stderr mean, and the exit
code: vulnerabilities fail; an unreachable or silent service is said loudly and fails only
with AUDIT_STRICT=1; packages the service does not know are listed."""

from __future__ import annotations

import json

import pytest

from tools.audit import EXIT_OK, EXIT_UNAUDITED, EXIT_VULNERABLE, classify, main, verdict


def _json(*dependencies: dict[str, object]) -> str:
    return json.dumps({"dependencies": list(dependencies), "fixes": []})


CLEAN = {"name": "fastapi", "version": "0.110.0", "vulns": []}
EDITABLE = {"name": "skyhelm", "skip_reason": "distribution marked as editable"}
UNKNOWN = {"name": "private-pkg", "skip_reason": "Dependency not found on PyPI"}
VULNERABLE = {
    "name": "starlette",
    "version": "0.27.0",
    "vulns": [{"id": "PYSEC-2024-1", "fix_versions": ["0.36.2"]}],
}


def test_clean_packages_pass_and_name_the_unknown_ones() -> None:
    code, lines = verdict(classify(0, _json(CLEAN, EDITABLE, UNKNOWN), ""), strict=True)
    assert code == EXIT_OK
    assert lines[0] == "pip-audit: 1 packages audited, no known vulnerabilities"
    assert any("private-pkg" in line for line in lines)
    assert not any("skyhelm" in line for line in lines)


def test_a_vulnerability_fails_with_its_id_and_fix() -> None:
    code, lines = verdict(classify(1, _json(CLEAN, VULNERABLE), ""), strict=False)
    assert code == EXIT_VULNERABLE
    assert "starlette 0.27.0: PYSEC-2024-1 (fixed in 0.36.2)" in lines[1]


@pytest.mark.parametrize("strict", [False, True])
def test_an_unreachable_service_is_said_and_fails_only_when_strict(strict: bool) -> None:
    stderr = (
        "Traceback ...\nrequests.exceptions.ConnectionError: HTTPSConnectionPool("
        "host='api.osv.dev', port=443): Max retries exceeded (Failed to resolve 'api.osv.dev')"
    )
    report = classify(1, None, stderr)
    assert report.unreachable is not None
    assert "ConnectionError" in report.unreachable
    code, lines = verdict(report, strict)
    assert code == (EXIT_UNAUDITED if strict else EXIT_OK)
    assert any("NOT audited" in line for line in lines)


def test_a_service_that_knows_no_package_counts_as_not_audited() -> None:
    # a mirror without PyPI's JSON API: pip-audit itself says "No known vulnerabilities"
    report = classify(0, _json(EDITABLE, UNKNOWN, {**UNKNOWN, "name": "other"}), "")
    assert report.audited == []
    assert report.unreachable is not None
    assert "none of the 2 packages" in report.unreachable
    assert verdict(report, strict=True)[0] == EXIT_UNAUDITED


def test_main_runs_pip_audit_and_reports(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from tools import audit

    seen: list[list[str]] = []

    def fake_run(extra: list[str]) -> audit.Report:
        seen.append(list(extra))
        return classify(0, _json(CLEAN), "")

    monkeypatch.setattr(audit, "run", fake_run)
    monkeypatch.setenv("AUDIT_STRICT", "1")
    assert main(["-s", "osv"]) == EXIT_OK
    assert seen == [["-s", "osv"]]
    assert "1 packages audited" in capsys.readouterr().out
