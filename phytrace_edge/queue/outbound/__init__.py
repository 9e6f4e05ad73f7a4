"""The queue's sending side: claims (batches leased for the live or the backfill lane),
leases, who holds the queue (the service, processes with open claims), and dead
letters (events PhyCloud rejected for good).
"""
