"""The queue file itself: its one connection and lock, opening it safely (place,
permissions, integrity, quarantine), schema migrations, SQLite's errors in the
operator's words, the rows and counters, the heartbeat row, and whether the file is
still where QUEUE_PATH says.
"""
