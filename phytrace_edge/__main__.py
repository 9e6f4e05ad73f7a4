"""``python -m phytrace_edge`` runs the CLI."""

from phytrace_edge.cli import main

raise SystemExit(main())
