"""The parser of ``INCIDENT_TRIGGERS``: topic conditions that open an incident, as text
(``/estop data == true; /delivery/status payload.delivery_state == failed``) or as a
TOML list of such strings. Stdlib only, like every parser on the start-up path."""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the incident package is imported when INCIDENT_TRIGGERS is given
    from phytrace_edge.incident.triggers import Condition

MAX_CONDITIONS = 32
ALLOWED = (
    "conditions 'TOPIC FIELD OP VALUE' separated by ';' (FIELD a dotted path into the "
    "topic's reading, OP one of == != >= <= > <, VALUE true, false, a number or a "
    "word), e.g. '/estop data == true; /delivery/status payload.delivery_state == failed'"
)
_TOPIC = r"(/[A-Za-z0-9_~{}]+)+"
_PATH = r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*"
_CONDITION = re.compile(
    rf"\s*(?P<topic>{_TOPIC})\s+(?P<path>{_PATH})\s*(?P<op>==|!=|>=|<=|>|<)\s*(?P<value>\S.*?)\s*"
)


def incident_triggers(raw: Any) -> tuple[Condition, ...]:
    """INCIDENT_TRIGGERS -> its conditions; ValueError(ALLOWED) for anything else."""
    from phytrace_edge.incident.triggers import Condition

    if isinstance(raw, list) and all(isinstance(item, str) for item in raw):
        parts = raw
    elif isinstance(raw, str) and len(raw) <= 16 * 1024:
        parts = [part for part in raw.split(";") if part.strip()]
    else:
        raise ValueError(ALLOWED)
    if len(parts) > MAX_CONDITIONS:
        raise ValueError(ALLOWED)
    conditions = []
    for part in parts:
        found = _CONDITION.fullmatch(part)
        if found is None:
            raise ValueError(ALLOWED)
        path = tuple(found["path"].split("."))
        conditions.append(Condition(found["topic"], path, found["op"], _value(found["value"])))
    if len(set(conditions)) < len(conditions):
        raise ValueError(ALLOWED)
    return tuple(conditions)


def _value(text: str) -> Any:
    """A JSON scalar (true, 2.5, "a b") as itself; any other word as a string."""
    try:
        value = json.loads(text)
    except ValueError:
        return text
    if isinstance(value, (dict, list)):
        raise ValueError(ALLOWED)
    return value
