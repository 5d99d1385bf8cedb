"""Every generator's --check fails on a stale file and passes once it has written it again
(each generated file's content is checked against its source in its own module)."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest

from tools import gen_calls_js, gen_client, gen_link_state, gen_wire_js


@pytest.mark.parametrize(
    "generator", [gen_calls_js, gen_client, gen_link_state, gen_wire_js],
    ids=lambda g: g.__name__.rsplit(".", 1)[-1],
)  # fmt: skip
def test_check_mode_fails_on_a_stale_file(
    generator: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    stale = tmp_path / Path(generator.OUT).name
    stale.write_text("# old\n")
    monkeypatch.setattr(generator, "OUT", stale)
    assert generator.main(["--check"]) == 1
    assert generator.main([]) == 0
    assert generator.main(["--check"]) == 0
