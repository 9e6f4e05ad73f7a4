"""Room on the disk: the byte and event caps and what a full queue drops, thinning
before dropping, the rules for a full volume, the reserve file, the volume's real
free space, and periodic upkeep (TTL expiry, giving space back).
"""
