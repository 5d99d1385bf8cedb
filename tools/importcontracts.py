"""An import-linter contract type that forbids import cycles between modules.

import-linter's own ``acyclic_siblings`` contract looks for cycles between the children of a
package, each child with its descendants squashed into it; a cycle that runs through a
package's ``__init__`` and one of its own modules (``server.link`` → ``server.link.vehicle`` →
``server.link``) is invisible to it. This contract looks at modules one by one, so any
cycle fails it, whichever packages it crosses, and whether its imports sit at the top of a
module, inside a function or under ``if TYPE_CHECKING`` (grimp sees all three).

Registered in pyproject.toml, ``[tool.importlinter] contract_types``::

    acyclic_modules: tools.importcontracts.AcyclicModulesContract
"""

from __future__ import annotations

from collections import deque
from typing import Any

import grimp
from importlinter.application import contract_utils, output
from importlinter.application.contract_utils import AlertLevel
from importlinter.domain import fields
from importlinter.domain.contract import Contract, ContractCheck
from importlinter.domain.helpers import module_expressions_to_modules


class AcyclicModulesContract(Contract):
    """No module of ``packages`` (or below them) reaches itself through its imports.

    Options: ``packages`` (module expressions), ``ignore_imports`` (as in other contracts).
    """

    type_name = "acyclic_modules"

    packages = fields.SetField(subfield=fields.ModuleExpressionField())
    ignore_imports = fields.SetField(subfield=fields.ImportExpressionField(), required=False)
    unmatched_ignore_imports_alerting = fields.EnumField(AlertLevel, default=AlertLevel.ERROR)

    def check(self, graph: grimp.ImportGraph, verbose: bool) -> ContractCheck:
        removal = contract_utils.remove_ignored_imports_and_report(
            graph=graph,
            ignore_imports=self.ignore_imports,  # type: ignore[arg-type]
            unmatched_alerting=self.unmatched_ignore_imports_alerting,  # type: ignore[arg-type]
        )
        roots = module_expressions_to_modules(
            graph,
            sorted(self.packages),  # type: ignore[arg-type]
            raise_if_unmatched=True,
        )
        modules: set[str] = set()
        for root in roots:
            modules.add(root.name)
            modules |= graph.find_descendants(root.name)
        imports = {
            module: graph.find_modules_directly_imported_by(module) & modules
            for module in modules
        }
        components = sorted(sorted(c) for c in _cyclic_components(imports))
        rendered = [
            {
                "modules": component,
                "cycle": [
                    _import_lines(graph, importer, imported)
                    for importer, imported in _one_cycle(set(component), imports)
                ],
            }
            for component in components
        ]
        output.verbose_print(verbose, f"{len(modules)} modules, {len(components)} tangle(s).")
        return ContractCheck(
            kept=not components,
            warnings=list(removal.warnings),
            ignored_import_count=removal.ignored_import_count,
            metadata={"cycles": rendered},
        )

    def render_broken_contract(self, check: ContractCheck) -> None:
        tangles: list[dict[str, list[str]]] = check.metadata["cycles"]
        for tangle in tangles:
            modules = tangle["modules"]
            output.print_error(f"{len(modules)} modules import each other: {', '.join(modules)}")
            output.print("One of their cycles:")
            for step in tangle["cycle"]:
                output.indent_cursor()
                output.print(step)
            output.new_line()


def _cyclic_components(imports: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components that hold a cycle (Tarjan's algorithm, iteratively)."""
    index: dict[str, int] = {}
    lowlink: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    components: list[set[str]] = []
    for start in sorted(imports):
        if start in index:
            continue
        work: list[tuple[str, list[str]]] = [(start, sorted(imports[start]))]
        index[start] = lowlink[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            module, pending = work[-1]
            if pending:
                imported = pending.pop()
                if imported not in index:
                    index[imported] = lowlink[imported] = len(index)
                    stack.append(imported)
                    on_stack.add(imported)
                    work.append((imported, sorted(imports[imported])))
                elif imported in on_stack:
                    lowlink[module] = min(lowlink[module], index[imported])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                lowlink[parent] = min(lowlink[parent], lowlink[module])
            if lowlink[module] == index[module]:
                component: set[str] = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.add(member)
                    if member == module:
                        break
                if len(component) > 1 or module in imports[module]:
                    components.append(component)
    return components


def _one_cycle(component: set[str], imports: dict[str, set[str]]) -> list[tuple[str, str]]:
    """The shortest cycle through the component's first module, as (importer, imported)."""
    first = min(component)
    came_from: dict[str, str] = {}
    queue = deque([first])
    while queue:
        module = queue.popleft()
        for imported in sorted(imports[module] & component):
            if imported == first:
                path = [(module, first)]
                while module != first:
                    path.append((came_from[module], module))
                    module = came_from[module]
                return path[::-1]
            if imported not in came_from:
                came_from[imported] = module
                queue.append(imported)
    raise AssertionError(f"no cycle through {first}")  # a component always has one


def _import_lines(graph: grimp.ImportGraph, importer: str, imported: str) -> str:
    details: list[dict[str, Any]] = list(
        graph.get_import_details(importer=importer, imported=imported)
    )
    lines = ", ".join(f"l.{d['line_number']}" for d in details)
    return f"{importer} -> {imported} ({lines})" if lines else f"{importer} -> {imported}"
