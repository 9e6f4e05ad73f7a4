"""Hand-carry: a robot's backlog on a USB stick for sites without a network. ``format``
(the MCAP file, its manifest, the writer), ``reader`` and ``legacy_phx`` (0.1.0's
files, read-only), ``report`` (what a file holds, for ``inspect``) and ``transfer``
(the backlog into files with ``export``, files back to PhyCloud with ``import``).
"""
