"""Write the Python client's table-made methods (clients/python/skyhelm_client/generated.py)
from the wire's call table (skyhelm_wire.calls).

    python -m tools.gen_client           # rewrite generated.py
    python -m tools.gen_client --check   # exit 1 if the checked-in file is not current

Every call of the table that ``skyhelm_client.calls.Calls`` does not write by hand
(``Calls.BY_HAND``) becomes a method of the blocking client (``SyncCalls``) and of the
asyncio one (``AsyncCalls``), named after the call (``Calls.METHOD_NAMES`` renames one):
its path parameters positional, its body's and query's fields keyword arguments, and its
answer the table's model, validated (``Answer[Model]``; ``CommandResult`` for a command;
a list of them for a list; ``bytes`` for a body that is not JSON; None for 204; the JSON
(``Any``) for an answer the table gives no model, e.g. ``dict[str, Any]``).
"""

from __future__ import annotations

import ast
import json
import types
from functools import cache
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin

from pydantic import BaseModel

from skyhelm_wire.calls import API_PREFIX, CALLS, CallSpec
from skyhelm_wire.commands import CommandResultOut
from skyhelm_wire.intents import IntentOut
from tools.generated import write_or_check

CLIENT = Path(__file__).resolve().parent.parent / "clients" / "python" / "skyhelm_client"
OUT = CLIENT / "generated.py"
COMMAND = "python -m tools.gen_client"
# the type arguments of Calls for each client (calls.py: what each sender returns)
SYNC_ARGS = (
    "CommandResult", "Lease", "State", "float | None", "None", "Answer[IntentOut]",
    "Answer[SentSetpointOut]", "ParamValues", "list[Answer[AuditEntryOut]]",
)  # fmt: skip


@cache
def hand_written() -> tuple[frozenset[str], dict[str, str]]:
    """``Calls.BY_HAND`` and ``Calls.METHOD_NAMES``, read from calls.py's source: importing
    the client would import the file this writes."""
    tree = ast.parse((CLIENT / "calls.py").read_text())
    values: dict[str, Any] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and node.name == "Calls":
            for item in node.body:
                if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                    value = item.value
                    if isinstance(value, ast.Call):  # frozenset({...})
                        value = value.args[0]
                    if value is not None:
                        values[item.target.id] = ast.literal_eval(value)
    return frozenset(values["BY_HAND"]), dict(values["METHOD_NAMES"])


class _Imports:
    def __init__(self) -> None:
        self.names: set[tuple[str, str]] = set()

    def add(self, kind: type[Any]) -> str:
        if kind.__module__ != "builtins":
            self.names.add((kind.__module__, kind.__name__))
        return kind.__name__


def _type(kind: Any, imports: _Imports) -> str:
    """A field's annotation as Python source (constraints dropped: the server checks them,
    and the body's model when the call is built)."""
    origin, args = get_origin(kind), get_args(kind)
    if origin is Annotated:
        return _type(args[0], imports)
    if kind is type(None):
        return "None"
    if kind is Any:
        return "Any"
    if origin is Literal:
        return f"Literal[{', '.join(json.dumps(arg) for arg in args)}]"
    if origin in (Union, types.UnionType):
        return " | ".join(_type(arg, imports) for arg in args)
    if origin in (list, dict, tuple):
        return f"{origin.__name__}[{', '.join(_type(arg, imports) for arg in args)}]"
    if isinstance(kind, type):
        return imports.add(kind)
    raise ValueError(f"no source for the annotation {kind!r}")


def _default(value: Any) -> str:
    if value is None or isinstance(value, bool | int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    raise ValueError(f"no source for the default {value!r}")


def _fields(model: type[BaseModel] | None, imports: _Imports) -> list[tuple[str, str]]:
    """(name, "name: type = default") of each field."""
    if model is None:
        return []
    fields = []
    for name, field in model.model_fields.items():
        text = f"{name}: {_type(field.annotation, imports)}"
        if not field.is_required():
            text += f" = {_default(None if field.default_factory else field.default)}"
        fields.append((name, text))
    return fields


def _answer(call: CallSpec, imports: _Imports) -> tuple[str, str]:
    """The method's answer type and the sender with its arguments after the call."""
    answer = call.answer
    if answer is None:
        return "None", "_none(call)"
    if answer is bytes:
        return "bytes", "_bytes(call)"
    if answer is CommandResultOut:
        return "CommandResult", "_command(call)"
    if answer is IntentOut:
        return "Answer[IntentOut]", "_intent(call)"
    if get_origin(answer) is list:
        item = imports.add(get_args(answer)[0])
        return f"list[Answer[{item}]]", f"_typed_list(call, {item})"
    if not (isinstance(answer, type) and issubclass(answer, BaseModel)):
        return "Any", "_json(call)"  # JSON the table gives no model for, as it is
    model = imports.add(answer)
    return f"Answer[{model}]", f"_typed(call, {model})"


def _method(call: CallSpec, imports: _Imports, asynchronous: bool) -> str:
    name = hand_written()[1].get(call.name, call.name)
    path = _fields(call.path_params, imports)
    body = _fields(call.body if isinstance(call.body, type) else None, imports)
    query = _fields(call.query, imports)
    keywords = body + query
    parameters = ["self", *(text for _, text in path)]
    if keywords:
        parameters += ["*", *(text for _, text in keywords)]
    answer, sender = _answer(call, imports)
    returns = f"Coroutine[Any, Any, {answer}]" if asynchronous else answer
    arguments = [json.dumps(call.name)]
    if body:
        arguments.append(f"given({', '.join(f'{n}={n}' for n, _ in body)})")
    if query:
        arguments.append(f"params=query({', '.join(f'{n}={n}' for n, _ in query)})")
    if path:
        arguments.append(f"path={{{', '.join(f'{json.dumps(n)}: str({n})' for n, _ in path)}}}")
    signature = "".join(f"        {p},\n" for p in parameters)
    build = "".join(f"            {a},\n" for a in arguments)
    return (
        f"    def {name}(\n{signature}    ) -> {returns}:\n"
        f'        """{call.method} {API_PREFIX}{call.route}"""\n'
        f"        call = self._named(\n{build}        )\n"
        f"        return self.{sender}\n"
    )


def _client(kind: str, args: tuple[str, ...], asynchronous: bool, imports: _Imports) -> str:
    wrap = (lambda t: f"Coroutine[Any, Any, {t}]") if asynchronous else (lambda t: t)
    calls = [call for call in CALLS if call.name not in hand_written()[0]]
    methods = "\n".join(_method(call, imports, asynchronous) for call in calls)
    type_args = "".join(f"        {wrap(arg)},\n" for arg in args)
    return (
        f"class {kind}(\n    Calls[\n{type_args}    ]\n):\n"
        f'    """The table-made calls of the {"asyncio" if asynchronous else "blocking"}'
        ' client."""\n\n'
        "    @abstractmethod\n"
        f"    def _typed(self, call: Call, model: type[_M]) -> {wrap('Answer[_M]')}: ...\n\n"
        "    @abstractmethod\n"
        "    def _typed_list(self, call: Call, model: type[_M]) -> "
        f"{wrap('list[Answer[_M]]')}: ...\n\n"
        "    @abstractmethod\n"
        f"    def _bytes(self, call: Call) -> {wrap('bytes')}: ...\n\n"
        "    @abstractmethod\n"
        f"    def _json(self, call: Call) -> {wrap('Any')}: ...\n\n"
        f"{methods}"
    )


def generate() -> str:
    imports = _Imports()
    for name in ("Answer", "CommandResult", "Lease", "ParamValues", "State"):
        imports.names.add(("skyhelm_client.models", name))
    imports.names |= {("skyhelm_wire.intents", "IntentOut"),
                      ("skyhelm_wire.setpoints", "SentSetpointOut"),
                      ("skyhelm_wire.control", "AuditEntryOut")}  # fmt: skip
    sync = _client("SyncCalls", SYNC_ARGS, False, imports)
    asynchronous = _client("AsyncCalls", SYNC_ARGS, True, imports)
    by_module: dict[str, list[str]] = {}
    for module, name in imports.names:
        by_module.setdefault(module, []).append(name)
    lines = [
        f"from {module} import {', '.join(sorted(names))}"
        for module, names in sorted(by_module.items())
    ]
    local = [line for line in lines if line.startswith("from skyhelm_")]
    body = f"{sync}\n\n{asynchronous}"
    typing_names = ["Any", "Literal", "TypeVar"] if "Literal[" in body else ["Any", "TypeVar"]
    helpers = [name for name in ("given", "query") if f"{name}(" in body]
    return (
        f"# Generated by `{COMMAND}` from skyhelm_wire.calls: do not edit.\n"
        '"""Every call of the wire\'s table the client does not write by hand (calls.py), as a\n'
        "method of the blocking (:class:`SyncCalls`) and the asyncio (:class:`AsyncCalls`)\n"
        'client: the table\'s method, path and answer model."""\n\n'
        "from __future__ import annotations\n\n"
        "from abc import abstractmethod\n"
        "from collections.abc import Coroutine\n"
        f"from typing import {', '.join(typing_names)}\n\n"
        "from pydantic import BaseModel\n\n"
        f"from skyhelm_client.calls import {', '.join(['Call', 'Calls', *helpers])}\n"
        + "".join(f"{line}\n" for line in local)
        + "\n"
        '_M = TypeVar("_M", bound=BaseModel)\n\n\n'
        f"{body}"
    )


def main(argv: list[str] | None = None) -> int:
    return write_or_check(argv, __doc__, OUT, generate, COMMAND)


if __name__ == "__main__":
    raise SystemExit(main())
