"""Generate ``phytrace_edge/udm/validator_generated.py``: the UDM validator as Python
code, made once here instead of in every bridge at start.

    .venv/bin/python tools/generate_validator.py           # rewrite it
    .venv/bin/python tools/generate_validator.py --check   # exit 1 if it is stale

fastjsonschema turns the schema (its ``$ref``s inlined, ``udm.schema.inline_refs``)
into 550 KB of Python. Compiled in the bridge at start that took a 34 MiB peak and left
8.5 MiB mapped after the heap was trimmed; imported from the installed module's
bytecode it costs 0.5 MiB (docs/benchmarks.md, "Footprint"). The module records the
sha256 of the schema file it was made from; ``udm.schema`` uses it only when that
matches the packaged schema, and compiles the schema otherwise.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from phytrace_edge.udm.schema import GENERATED, generated_source, schema_sha256  # noqa: E402

TARGET = ROOT / "phytrace_edge" / "udm" / f"{GENERATED.rsplit('.', 1)[-1]}.py"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the file is stale")
    args = parser.parse_args()
    if args.check:
        recorded = TARGET.read_text().split("SCHEMA_SHA256 = ", 1)[1].split("\n", 1)[0]
        if recorded.strip('"') != schema_sha256():
            print(f"{TARGET} is stale: run tools/generate_validator.py")
            return 1
        return 0
    TARGET.write_text(generated_source())
    print(f"wrote {TARGET} ({TARGET.stat().st_size:,} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
