"""The package keeps the shape runtime/wiring.py describes: who may import whom, one
owner per resource, and no stage that reads the configuration or the environment.

Imports are read from the source (every import statement, also those inside functions
and under TYPE_CHECKING, and ``importlib.import_module`` calls), so a lazy import cannot
hide a dependency.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "phytrace_edge"
BASE = {"udm", "units", "redact", "errors"}
PACKAGE_LEVEL = {"phytrace_edge", "phytrace_edge.__version__"}  # the version, for everyone

# The dependency rule of runtime/wiring.py's docstring: each component may import the
# components listed here and, transitively, what those may import.
DECLARED: dict[str, set[str]] = {
    "package": {"cli", "runtime"},  # phytrace_edge/__init__.py and __main__.py
    "cli": {"runtime", "stub", "sim"},
    "runtime": {"config"},
    "config": {"ship", "builder"},
    "ship": {"queue"},
    "queue": set(),
    "builder": {"ingest"},
    "ingest": {"sim"},
    "sim": set(),
    "stub": set(),
    "udm": {"errors"},
    "units": set(),
    "redact": set(),
    "errors": set(),
    "launch": set(),
}


def component(module: str) -> str:
    """``phytrace_edge.queue.store`` -> ``queue``; ``phytrace_edge`` -> ``package``."""
    parts = module.split(".")
    if len(parts) == 1 or parts[1] in ("__init__", "__main__"):
        return "package"
    return parts[1]


def module_name(path: Path) -> str:
    relative = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = [part for part in relative.parts if part != "__init__"]
    return ".".join(parts)


def imported_modules(tree: ast.AST, importer: str) -> set[str]:
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the importer's package
                base = importer.rsplit(".", node.level)[0]
                target = f"{base}.{node.module}" if node.module else base
            else:
                target = node.module or ""
            found.add(target)
            found |= {f"{target}.{alias.name}" for alias in node.names}
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.add(node.args[0].value)
    return found


@cache
def import_graph() -> dict[str, set[str]]:
    """Module -> the modules it imports (all of them, not only the package's)."""
    graph = {}
    for path in PACKAGE.rglob("*.py"):
        name = module_name(path)
        graph[name] = imported_modules(ast.parse(path.read_text("utf-8")), name)
    return graph


def edges(source: str) -> set[str]:
    """What ``source`` may import directly: its declared components, and the base."""
    return DECLARED[source] | (set() if source in BASE else BASE)


def reachable(source: str) -> set[str]:
    found, todo = set(), [source]
    while todo:
        for target in edges(todo.pop()):
            if target not in found:
                found.add(target)
                todo.append(target)
    return found


def allowed(source: str) -> set[str]:
    return reachable(source) | {source}


def test_every_component_is_declared() -> None:
    components = {component(name) for name in import_graph()}
    assert components <= set(DECLARED), components - set(DECLARED)


def test_the_declared_rule_has_no_cycles() -> None:
    for source in DECLARED:
        assert source not in reachable(source), f"{source} can reach itself"


def test_imports_follow_the_dependency_rule() -> None:
    violations = []
    for module, imports in sorted(import_graph().items()):
        source = component(module)
        for target in sorted(imports):
            if target.split(".")[0] != "phytrace_edge" or target in PACKAGE_LEVEL:
                continue
            if component(target) not in allowed(source):
                violations.append(f"{module} -> {target}")
    assert not violations, "\n".join(violations)


def importers_of(prefix: str) -> set[str]:
    return {
        module
        for module, imports in import_graph().items()
        if any(target == prefix or target.startswith(prefix + ".") for target in imports)
    }


def test_exactly_one_module_imports_rclpy() -> None:
    assert importers_of("rclpy") == {"phytrace_edge.ingest.sources.ros"}


def test_only_the_queue_opens_sqlite_and_only_the_transport_and_stub_talk_http() -> None:
    sqlite = {m for m in importers_of("sqlite3") if component(m) != "queue"}
    assert sqlite == set(), sqlite
    http = {m for m in importers_of("httpx") if component(m) != "stub"}
    assert http == {"phytrace_edge.ship.transport"}


def test_no_stage_reads_the_configuration() -> None:
    readers = {m for m in importers_of("phytrace_edge.config") if component(m) != "config"}
    assert readers <= {"phytrace_edge.runtime.wiring", "phytrace_edge.runtime.simulation"} | {
        m for m in readers if component(m) == "cli"
    }


def test_only_the_cli_reads_the_process_environment() -> None:
    readers = set()
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text("utf-8"))):
            if (
                isinstance(node, ast.Attribute)
                and node.attr in ("environ", "getenv")
                and getattr(node.value, "id", None) == "os"
            ):
                readers.add(module_name(path))
    # launch files run inside `ros2 launch`, not the bridge
    assert {m for m in readers if component(m) not in ("cli", "launch")} == set()


def test_modules_stay_small_enough_to_read_in_one_sitting() -> None:
    sizes = {
        module_name(path): len(path.read_text("utf-8").splitlines())
        for path in PACKAGE.rglob("*.py")
    }
    # the IDL types and the mock's message classes are tables, not logic
    tables = {"phytrace_edge.ingest.sources.dds_types", "phytrace_edge.sim.mock_ros.messages"}
    large = {m: n for m, n in sizes.items() if n > 400 and m not in tables}
    assert not large, large
