"""Built-in scenarios; importing this package registers them."""

from navreplay.sim.scenarios import vehicle  # noqa: F401
from navreplay.sim.scenarios import ship_transfer_alignment  # noqa: F401
from navreplay.sim.scenarios import gimpo  # noqa: F401
from navreplay.sim.scenarios import underwater  # noqa: F401
