"""Importing this module registers every built-in filter (one import per filter module)."""
from navreplay.filters import transfer_alignment  # noqa: F401
from navreplay.filters import vector_matching  # noqa: F401
from navreplay.filters import rpm_aided_ins  # noqa: F401
from navreplay.filters import ins  # noqa: F401
from navreplay.filters import gps_ins  # noqa: F401
