"""Schema migrations: numbered SQL files applied in order, tracked by ``user_version``.

The files live in the repository's ``migrations/`` folder; the wheel carries them in a
``migrations`` folder beside this module (``force-include`` in pyproject.toml). A
database at version N gets files N+1...
applied, each in its own transaction, so an upgrade interrupted by a crash resumes.
"""

from __future__ import annotations

import re
import sqlite3
from pathlib import Path

_NUMBERED = re.compile(r"^(\d{4})_[a-z0-9_]+\.sql$")


def migrations_dir() -> Path:
    """The packaged migrations, or the repository's folder in a source checkout."""
    packaged = Path(__file__).with_name("migrations")
    return packaged if packaged.is_dir() else Path(__file__).parents[3] / "migrations"


def migration_files(folder: Path | None = None) -> list[tuple[int, Path]]:
    """(version, file) for every migration, in order; versions must be 1, 2, 3, ..."""
    folder = folder or migrations_dir()
    found = sorted(
        (int(match.group(1)), path)
        for path in folder.iterdir()
        if (match := _NUMBERED.match(path.name))
    )
    versions = [version for version, _ in found]
    if versions != list(range(1, len(found) + 1)):
        raise RuntimeError(f"migrations in {folder} are not numbered 1..n: {versions}")
    return found


def latest_version() -> int:
    """The schema version this code writes: the number of the last migration."""
    return len(migration_files())


def migrate(connection: sqlite3.Connection, up_to: int | None = None) -> int:
    """Apply pending migrations (all, or up to version ``up_to``); the new version."""
    current = connection.execute("PRAGMA user_version").fetchone()[0]
    for version, path in migration_files():
        if version <= current or (up_to is not None and version > up_to):
            continue
        script = path.read_text("utf-8")
        connection.executescript(f"BEGIN;\n{script}\nPRAGMA user_version = {version};\nCOMMIT;")
        current = version
    return int(current)
