"""Seeds of the slow reproduction tests (`make reproduce-tests`).

Every acceptance band must hold at any seed, not only at the seeds the documentation quotes:
the slow tests run each full campaign at every seed of this list, which mixes the documented
seed 0 with seeds that were never used to choose a model or a tuning value.
"""

SLOW_SEEDS = (0, 777, 4242)
