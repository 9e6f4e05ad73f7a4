"""The package keeps the shape runtime/wiring.py describes: who may import whom, one
owner per resource, no stage that reads the configuration or the environment, and no
import cycle at all.

Imports are read from the source: every import statement, also those inside functions
and under TYPE_CHECKING, ``importlib.import_module`` calls, and strings that name a
module of the package (``"phytrace_edge.ingest.sources.ros:RosSource"``; an f-string
``f"phytrace_edge.cli.{name}"`` names every module it could), so neither a lazy nor a
string import can hide a dependency. Cycles are looked for among the imports that run
(those under TYPE_CHECKING only name types).
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "phytrace_edge"
BASE = {"udm", "units", "redact", "errors", "_version", "host_clock", "host_memory", "durable"}
MODULE_STRING = re.compile(r"^phytrace_edge(\.[a-z_0-9]+)+(:\w+)?$")

# The dependency rule of runtime/wiring.py's docstring: each component may import the
# components listed here and, transitively, what those may import.
DECLARED: dict[str, set[str]] = {
    "package": {"cli", "runtime"},  # phytrace_edge/__init__.py and __main__.py
    "cli": {"runtime", "stub", "sim", "handcarry"},
    "runtime": {"config"},
    "config": {"ship", "builder", "incident"},
    "ship": {"queue"},
    "queue": set(),
    "handcarry": {"queue"},
    "incident": {"builder"},
    "builder": {"ingest"},
    "ingest": {"sim"},
    "sim": set(),
    "stub": set(),
    "udm": {"errors"},
    "units": set(),
    "redact": set(),
    "errors": set(),
    "_version": set(),
    "host_clock": set(),
    "durable": set(),
    "host_memory": set(),
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


@cache
def package_modules() -> frozenset[str]:
    """Every module of the package (a folder without ``__init__.py`` runs no code)."""
    return frozenset(module_name(path) for path in PACKAGE.rglob("*.py"))


def resolve(target: str) -> str:
    """The package module an import of ``target`` runs: ``phytrace_edge.queue.store.X``
    -> ``phytrace_edge.queue.store``; anything outside the package as it is."""
    if target.split(".")[0] != "phytrace_edge":
        return target
    parts = target.split(".")
    for end in range(len(parts), 0, -1):
        prefix = ".".join(parts[:end])
        folder = PACKAGE.parent.joinpath(*parts[:end])
        if prefix in package_modules() or folder.is_dir():  # a bare folder runs no code
            return prefix
    return target


def type_checking_only(tree: ast.AST) -> set[int]:
    """The nodes under ``if TYPE_CHECKING:``: imports that never run."""
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            skipped |= {id(inner) for child in node.body for inner in ast.walk(child)}
    return skipped


def named_modules(node: ast.AST, importer: str) -> set[str]:
    """What one node imports, or names as a module in a string."""
    if isinstance(node, ast.Import):
        return {alias.name for alias in node.names}
    if isinstance(node, ast.ImportFrom):
        target = node.module or ""
        if node.level:  # relative: resolve against the importer's package
            base = importer.rsplit(".", node.level)[0]
            target = f"{base}.{target}" if target else base
        # `from package import name` runs package.name when that is a module
        names = {f"{target}.{alias.name}" for alias in node.names}
        modules = {name for name in names if resolve(name) == name}
        return modules | ({target} if modules != names else set())
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return {node.value.split(":")[0]} if MODULE_STRING.match(node.value) else set()
    if isinstance(node, ast.JoinedStr) and node.values:
        prefix = node.values[0]
        if isinstance(prefix, ast.Constant) and MODULE_STRING.match(f"{prefix.value}x"):
            return {m for m in package_modules() if m.startswith(prefix.value)}
    if (
        isinstance(node, ast.Call)
        and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
        and node.args
        and isinstance(node.args[0], ast.Constant)
        and isinstance(node.args[0].value, str)
    ):
        return {node.args[0].value}
    return set()


def imported_modules(tree: ast.AST, importer: str, running_only: bool = False) -> set[str]:
    skipped = type_checking_only(tree) if running_only else set()
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) not in skipped:
            found |= {resolve(name) for name in named_modules(node, importer)}
    return found - {importer}


@cache
def import_graph(running_only: bool = False) -> dict[str, set[str]]:
    """Module -> the modules it imports (all of them, not only the package's)."""
    graph = {}
    for path in PACKAGE.rglob("*.py"):
        name = module_name(path)
        tree = ast.parse(path.read_text("utf-8"))
        graph[name] = imported_modules(tree, name, running_only)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected groups of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[set[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        for target in graph.get(module, set()) & graph.keys():
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            group = set()
            while not group or module not in group:
                group.add(stack.pop())
            if len(group) > 1:
                found.append(group)

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return found


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
            if target.split(".")[0] != "phytrace_edge":
                continue
            if component(target) not in allowed(source):
                violations.append(f"{module} -> {target}")
    assert not violations, "\n".join(violations)


def test_no_module_is_part_of_an_import_cycle() -> None:
    assert cycles(import_graph(running_only=True)) == []


def test_the_cycle_finder_finds_one() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]


def test_string_and_lazy_imports_are_seen() -> None:
    registry = import_graph()["phytrace_edge.ingest.sources.registry"]
    assert "phytrace_edge.ingest.sources.ros" in registry  # "module:Class" strings
    commands = import_graph()["phytrace_edge.cli"]
    assert {"phytrace_edge.cli.run", "phytrace_edge.cli.import_files"} <= commands  # f-string
    assert "phytrace_edge.runtime.simulation" in import_graph()["phytrace_edge"]  # lazy


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
    assert http == {"phytrace_edge.ship.transport", "phytrace_edge.ship.bounded_http"}


def test_no_stage_reads_the_configuration() -> None:
    """Settings are read by runtime/options.py and runtime/wiring.py (and the CLI,
    which loads them), the health thresholds by runtime/health.py (for ``status``'s
    start-up); run_simulation only hands its caller's settings to wiring."""
    readers = {m for m in importers_of("phytrace_edge.config") if component(m) != "config"}
    runtime = {
        "phytrace_edge.runtime.options",
        "phytrace_edge.runtime.wiring",
        "phytrace_edge.runtime.health",
    }
    passes_through = {"phytrace_edge.runtime.simulation"}
    assert readers - runtime - passes_through == {m for m in readers if component(m) == "cli"}


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


def test_every_folder_of_code_is_a_package() -> None:
    """A folder of modules is a component or a concept with a docstring saying what it
    holds (``__init__.py``), not a bag of files. Module size has no cap: a module is
    split where its concept splits (docs/architecture.md, "Review rules")."""
    folders = {path.parent for path in PACKAGE.rglob("*.py") if "__pycache__" not in path.parts}
    without = sorted(
        str(f.relative_to(PACKAGE)) for f in folders if not (f / "__init__.py").exists()
    )
    assert without == ["launch"]  # launch files are run by `ros2 launch`, not imported
