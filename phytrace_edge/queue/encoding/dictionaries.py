"""The zstd dictionaries a queue file's rows were compressed with.

Every dictionary a row was ever written with is kept in the file, so rows stay
readable after an upgrade ships a new packaged dictionary.
"""

from __future__ import annotations

from phytrace_edge.queue.encoding.codecs import Codecs, packaged_dictionary
from phytrace_edge.queue.storage.database import Database


def load_dictionaries(db: Database, codecs: Codecs, now: float) -> None:
    """Make the file's dictionaries usable by ``codecs``, and store the packaged one
    if this file does not have it yet."""
    for dict_id, content in db.read("SELECT dict_id, content FROM zstd_dictionaries"):
        codecs.add_dictionary(dict_id, content)
    if not db.read("SELECT 1 FROM zstd_dictionaries WHERE dict_id = ?", (codecs.dict_id,)):
        dict_id, content = packaged_dictionary()
        with db.transaction() as cursor:
            cursor.execute(
                "INSERT OR IGNORE INTO zstd_dictionaries(dict_id, content, added_at) "
                "VALUES (?, ?, ?)",
                (dict_id, content, now),
            )
