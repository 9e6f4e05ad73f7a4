"""The UDM JSON Schema shipped in the package (SCHEMA_FILE), and its validator.

The schema file is the contract PhyCloud and other languages use; this module compiles
it once (fastjsonschema generates Python code from it, pure Python, so it installs on
any robot) and reports the first failure of an event as the field path and the
offending value. The schema's ``$ref``s are inlined before compiling: each referenced
definition would otherwise be a generated function that formats its error-path string
on every call, which made validation 2.5x slower.
"""

from __future__ import annotations

import functools
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from typing import Any

import fastjsonschema

SCHEMA_VERSION = "1.2.0"
SCHEMA_FILE = f"udm-{SCHEMA_VERSION}.schema.json"

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SchemaViolation:
    """The first place an event breaks the schema."""

    path: str
    value: Any
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.message} (value: {self.value!r:.120})"


def load_schema() -> dict[str, Any]:
    """The UDM JSON Schema as a dict."""
    text = resources.files("phytrace_edge.udm").joinpath(SCHEMA_FILE).read_text("utf-8")
    schema: dict[str, Any] = json.loads(text)
    return schema


def inline_refs(schema: dict[str, Any]) -> dict[str, Any]:
    """The schema with every local ``#/definitions/x`` reference replaced by its body."""
    definitions = schema.get("definitions", {})

    def inline(node: Any) -> Any:
        if isinstance(node, dict):
            if "$ref" in node:
                return inline(definitions[node["$ref"].rsplit("/", 1)[-1]])
            return {key: inline(value) for key, value in node.items() if key != "definitions"}
        if isinstance(node, list):
            return [inline(item) for item in node]
        return node

    inlined: dict[str, Any] = inline(schema)
    return inlined


@functools.cache
def _compiled() -> Callable[[Any], Any]:
    return fastjsonschema.compile(inline_refs(load_schema()))


def prepare_validator() -> None:
    """Compile the validator now rather than at the first event: a service does it
    at start, then gives the compiler's memory back (``host_memory``)."""
    _compiled()


def find_violation(event: Any) -> SchemaViolation | None:
    """The first schema violation of ``event``, or None when it is valid."""
    try:
        _compiled()(event)
    except fastjsonschema.JsonSchemaValueException as exc:
        path = "/".join(str(part) for part in exc.path[1:]) or "(event)"
        return SchemaViolation("/" + path if path != "(event)" else path, exc.value, exc.message)
    return None


def check_event(event: Any, logger: logging.Logger = log) -> bool:
    """Validate ``event``; log a WARNING with the field path and value when it fails."""
    violation = find_violation(event)
    if violation is None:
        return True
    logger.warning(
        "UDM validation failed for event %s: %s",
        _event_id(event),
        violation,
    )
    return False


def _event_id(event: Any) -> str:
    return str(event.get("event_id", "?")) if isinstance(event, dict) else "?"


def event_type_schema(event_type: str) -> dict[str, Any]:
    """The UDM schema of one event type, standing alone: the definitions that type
    refers to (directly or through others) and nothing else, so a reader of one
    channel of a hand-carry file gets a schema it can compile by itself. A type the
    schema does not define gets the whole schema."""
    schema = load_schema()
    definitions = schema["definitions"]
    if event_type not in definitions:
        return schema
    needed: dict[str, Any] = {}
    waiting = [event_type]
    while waiting:
        name = waiting.pop()
        if name not in needed:
            needed[name] = definitions[name]
            waiting.extend(_local_refs(definitions[name]))
    base = schema["$id"].removesuffix(".schema.json")
    return {
        "$schema": schema["$schema"],
        "$id": f"{base}/{event_type}.schema.json",
        "title": f"{schema['title']}: {event_type}",
        "allOf": [{"$ref": f"#/definitions/{event_type}"}],
        "definitions": dict(sorted(needed.items())),
    }


def _local_refs(node: Any) -> list[str]:
    """The names of the definitions ``node`` refers to (``#/definitions/name``)."""
    if isinstance(node, dict):
        own = [node["$ref"].rsplit("/", 1)[-1]] if "$ref" in node else []
        return own + [name for value in node.values() for name in _local_refs(value)]
    if isinstance(node, list):
        return [name for item in node for name in _local_refs(item)]
    return []
