"""The PhyCloud dev stub: the HTTP API (``app``), its record (``store``), the live page
(``board``, ``page.html``), fault injection and validation."""
