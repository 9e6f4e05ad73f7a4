"""The PhyTrace Unified Data Model: ``schema`` (the JSON Schema shipped in the package
and its validator) and ``event`` (event ids and timestamps)."""
