"""navreplay: simulate navigation sensor recordings and replay estimation filters over them.

Conventions (used everywhere in the package)
--------------------------------------------
Frames
    n   local navigation frame, North-East-Down (NED).
    b   body frame, Forward-Right-Down (FRD): x forward, y right (starboard), z down.
    e   earth-centred earth-fixed (ECEF), WGS84.
    i   inertial.
Names carry frame and direction: ``v_n`` is a velocity resolved in n, ``f_b`` the specific force
in b, ``omega_ib_b`` the rate of b relative to i resolved in b, ``lever_arm_b`` a lever arm in b.
``C_nb`` maps b to n: ``v_n = C_nb @ v_b``.

Attitude
    Quaternions are Hamilton, scalar first, ``q = [q0, q1, q2, q3]``; ``q_nb`` rotates b to n so
    that ``C(q_nb) = C_nb``. Arrays in another order say so in their name (``q_nb_xyzw``) and exist
    only at the scipy / Rerun boundary. Euler angles are ZYX: ``C_nb = Rz(yaw) Ry(pitch) Rx(roll)``,
    stored as ``[roll, pitch, yaw]``.

Units
    SI and radians internally. Names carry a suffix only when they deviate: ``lat_deg``, ``t_ns``,
    ``bias_dph``. Datasheet units are converted once, at the configuration boundary, with the
    constants of :mod:`navreplay.core.units`.

Position
    Geodetic latitude and longitude in radians and ellipsoidal height in metres (WGS84);
    ``pos = [lat, lon, h]``.

Time
    int64 nanoseconds in files and sinks (``t_ns``); float seconds relative to the recording start
    inside filters (``t``).

Randomness
    Every random function takes a :class:`numpy.random.Generator`. A recording is a pure function of
    (scenario, parameters, seed): the same inputs give byte-identical files.
"""

__version__ = "0.1.0"
