"""One way to reach a plugin: outside server/link, only through Vehicle's own operations.

Vehicle holds its core and one plugin per MAVLink concern (``vehicle.offboard``, ...);
server.link.vehicle_operations defines each operation once, naming the plugin doing the work.
These tests keep code outside the link off the plugins (a name-based scan: an attribute
chain through a plugin's name, or a plugin taken off something named like a vehicle) and
each operation's signature equal to the plugin method it hands to.
"""

from __future__ import annotations

import ast
import inspect
from collections.abc import Callable, Iterator
from pathlib import Path

from server.link import vehicle as vehicle_module
from server.link.vehicle import Vehicle
from server.link.vehicle_operations import VehicleOperations

ROOT = Path(__file__).resolve().parents[1]
SERVER = ROOT / "server"


def _plugin_names() -> set[str]:
    """The attributes Vehicle.__init__ sets to a core or plugin object."""
    tree = ast.parse(Path(vehicle_module.__file__).read_text())
    classes = {
        alias.asname or alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        and (node.module or "").startswith(("server.link.plugins.", "server.link.core."))
        for alias in node.names
    }
    names = set()
    init = next(
        node for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef) and node.name == "__init__"
    )  # fmt: skip
    for node in ast.walk(init):
        if not (isinstance(node, ast.Assign) and isinstance(node.value, ast.Call)):
            continue
        func = node.value.func
        if not (isinstance(func, ast.Name) and func.id in classes):
            continue
        for target in node.targets:
            if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name):
                names.add(target.attr)
    return names


PLUGINS = _plugin_names()


def _terminal_name(node: ast.expr) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return ""


def reaches_a_plugin(source: str) -> Iterator[tuple[int, str]]:
    """(line, expression) for each ``<x>.<plugin>`` followed by an attribute, and each
    ``<vehicle>.<plugin>``."""
    nodes = list(ast.walk(ast.parse(source)))
    chained = {id(node.value) for node in nodes if isinstance(node, ast.Attribute)}
    for node in nodes:
        if not (isinstance(node, ast.Attribute) and node.attr in PLUGINS):
            continue
        if id(node) in chained or "vehicle" in _terminal_name(node.value).lower():
            yield node.lineno, ast.unparse(node)


def test_the_plugins_are_found_in_vehicle() -> None:
    assert {"core", "action", "offboard", "manual_control", "params", "telemetry"} <= PLUGINS
    assert {"telemetry_requests", "px4_events", "outage"} <= PLUGINS


def test_the_scan_finds_a_plugin_reached_from_outside() -> None:
    source = (
        "flying = vehicle.offboard.setpoint\n"
        "manual = self._vehicle.manual_control\n"
        "registry.get(1).action.arm()\n"
        "ok = vehicle.setpoint, self.action, vehicle.arm()\n"
    )
    assert sorted(line for line, _ in reaches_a_plugin(source)) == [1, 2, 3]


def test_code_outside_the_link_reaches_plugins_only_through_vehicle() -> None:
    found = [
        f"{path.relative_to(ROOT)}:{line}: {expr}"
        for path in sorted(SERVER.rglob("*.py"))
        if SERVER / "link" not in path.parents
        for line, expr in reaches_a_plugin(path.read_text())
    ]
    assert found == []


def _handed_to(function: Callable[..., object]) -> tuple[str, str] | None:
    """(plugin, method) when the function's body is one call of ``self.<plugin>.<method>``."""
    tree = ast.parse(inspect.cleandoc("\n" + inspect.getsource(function)))
    body = [
        node for node in tree.body[0].body  # type: ignore[attr-defined]
        if not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant))
    ]  # fmt: skip
    if len(body) != 1 or not isinstance(body[0], ast.Return | ast.Expr):
        return None
    call = body[0].value
    if isinstance(call, ast.Await):
        call = call.value
    if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)):
        return None
    owner = call.func.value
    if (
        isinstance(owner, ast.Attribute)
        and isinstance(owner.value, ast.Name)
        and owner.value.id == "self"
        and owner.attr in PLUGINS
    ):
        return owner.attr, call.func.attr
    return None


def test_each_operation_has_the_signature_of_the_plugin_method_it_hands_to() -> None:
    annotations = inspect.get_annotations(VehicleOperations)
    checked = []
    for name, function in vars(VehicleOperations).items():
        if name.startswith("_") or not inspect.isfunction(function):
            continue
        target = _handed_to(function)
        if target is None:
            continue
        plugin, method = target
        plugin_class = annotations[plugin]
        plugin_method = getattr(vars(vehicle_module)[plugin_class], method)
        ours = inspect.signature(function).parameters
        theirs = inspect.signature(plugin_method).parameters
        assert ours == theirs, name
        assert inspect.iscoroutinefunction(function) == inspect.iscoroutinefunction(
            plugin_method
        ), name
        assert plugin_class in (function.__doc__ or ""), name
        checked.append(name)
    assert {"arm", "set_setpoint", "hold_position_setpoint", "set_sticks", "stop_sticks"} <= set(
        checked
    )
    assert len(checked) >= 25


def test_vehicle_offers_the_operations_on_itself() -> None:
    for name in ("arm", "set_setpoint", "start_offboard", "set_sticks", "get_param"):
        assert getattr(Vehicle, name) is vars(VehicleOperations)[name]
