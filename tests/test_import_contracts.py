"""The acyclic_modules import-linter contract type (tools/importcontracts.py)."""

from __future__ import annotations

import grimp

from tools.importcontracts import AcyclicModulesContract


def _graph(*imports: tuple[str, str]) -> grimp.ImportGraph:
    graph = grimp.ImportGraph()
    for importer, imported in imports:
        for module in (importer, imported):
            graph.add_module(module)
        graph.add_import(importer=importer, imported=imported, line_number=3, line_contents="")
    graph.add_module("pkg")
    return graph


def _tangles(graph: grimp.ImportGraph) -> list[dict[str, list[str]]]:
    contract = AcyclicModulesContract(
        name="no cycles", session_options={}, contract_options={"packages": ["pkg"]}
    )
    check = contract.check(graph, verbose=False)
    assert check.kept == (not check.metadata["cycles"])
    tangles: list[dict[str, list[str]]] = check.metadata["cycles"]
    return tangles


def test_a_chain_without_a_way_back_is_kept() -> None:
    graph = _graph(("pkg.a", "pkg.b"), ("pkg.b", "pkg.c"), ("pkg.a", "pkg.c"))
    assert _tangles(graph) == []


def test_a_package_and_its_own_module_importing_each_other_is_a_cycle() -> None:
    # acyclic_siblings cannot see this one: the package's __init__ is no sibling of its module.
    tangles = _tangles(_graph(("pkg", "pkg.vehicle"), ("pkg.vehicle", "pkg")))
    assert [t["modules"] for t in tangles] == [["pkg", "pkg.vehicle"]]
    assert tangles[0]["cycle"] == ["pkg -> pkg.vehicle (l.3)", "pkg.vehicle -> pkg (l.3)"]


def test_each_tangle_is_named_with_all_its_modules_and_one_shortest_cycle() -> None:
    graph = _graph(
        ("pkg.x.a", "pkg.y.b"), ("pkg.y.b", "pkg.x.c"), ("pkg.x.c", "pkg.x.a"),
        ("pkg.x.a", "pkg.x.c"),
        ("pkg.p", "pkg.q"), ("pkg.q", "pkg.p"),
        ("pkg.outside", "pkg.p"),
    )
    tangles = _tangles(graph)
    assert [t["modules"] for t in tangles] == [
        ["pkg.p", "pkg.q"], ["pkg.x.a", "pkg.x.c", "pkg.y.b"]
    ]
    assert tangles[1]["cycle"] == ["pkg.x.a -> pkg.x.c (l.3)", "pkg.x.c -> pkg.x.a (l.3)"]
