"""Queue time (the clock every age, lease and schedule is read on) and the repair of
timestamps after a step of the wall clock.
"""
