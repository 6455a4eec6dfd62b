"""What every other package builds on: the in-memory data (:mod:`~navreplay.core.streams`:
streams, recordings, metadata), datasheet units (:mod:`~navreplay.core.units`), parameter
dataclasses from ``-p`` text and TOML (:mod:`~navreplay.core.params`), and the small numerics
shared by the simulator, the filters and the scoring: linear stochastic systems
(:mod:`~navreplay.core.lti`), chi-square quantiles (:mod:`~navreplay.core.chi2`) and numba's
compile setup (:mod:`~navreplay.core.jit`). It imports nothing else of navreplay."""
