"""Results that leave navreplay: CSV tables, TUM trajectories and an MCAP of
``nav_msgs/msg/Odometry`` estimates (docs/exports.md describes every file and column).

``navreplay run ... --export DIR`` writes, per filter label ``L`` (made file-safe):

``L.csv``
    One row per estimate: time, navigation solution, its predicted 1-sigma, the state vector and
    its 1-sigma, and with a reference the errors (estimate minus reference) and the NEES. Column
    names carry their unit, ``name [unit]``.
``L.tum``
    ``timestamp tx ty tz qx qy qz qw`` (evo's TUM format): absolute time [s], position [m] in
    the local ENU frame of :class:`LocalFrame`, orientation of base_link (FLU) in that frame.
``L.innovations.<measurement>.csv``
    One row per update of each measurement: time, the innovation of each row and its predicted
    1-sigma ``sqrt(S_ii)``, the NIS and its dof (the rows the filter declares, with their units;
    rows numbered ``0..m-1`` of unknown unit for a filter that declares none).
``reference.tum``
    The reference (truth) in the same frame, when the recording has one.
``estimates.mcap``
    One ``nav_msgs/msg/Odometry`` topic per filter (``/estimates/<L>/odom``) and the reference
    (``/reference/odom``), ROS 2 profile, CDR: header.frame_id ``map`` (ENU about the origin,
    REP-103/105), child_frame_id ``base_link`` (FLU), pose and twist with covariance.
``manifest.json``
    The origin, the frames, the files and every column with its unit and meaning.

``navreplay montecarlo ... --export DIR`` writes ``L.ensemble.csv`` (RMS, mean predicted sigma,
NEES mean and bounds over time) and ``L.nis.<measurement>.csv`` per filter.

Frames. navreplay works in NED / FRD; ROS in ENU / FLU. With ``T = [[0,1,0],[1,0,0],[0,0,-1]]``
(NED <-> ENU, a proper rotation, its own inverse) and ``F = diag(1,-1,-1)`` (FRD <-> FLU), an
estimate at (lat, lon, h) maps to the ENU frame at the origin through
``R = C_enu0<-ecef C_ecef<-ned(lat, lon)`` (``R = T`` at the origin itself):

    position   p_enu = C_enu0<-ecef (r_ecef - r0_ecef)
    attitude   C_enu0<-flu = R C_nb F
    covariance Sigma_pose  = blkdiag(R, R) Sigma_(pos_ned, phi) blkdiag(R, R)^T
               Sigma_twist = J Sigma_(v_n, phi) J^T,  J = F C_nb^T [I, -[v_n x]]
               (the body velocity v_b = C_nb^T v_n to first order in the attitude error phi,
               ``C_hat = (I - [phi x]) C``).

The twist's angular part is not estimated: zeros, with -1 on its covariance diagonal (the
sensor_msgs convention for "not available"); the same marks any pose or linear-velocity element
whose variance the filter does not hold.

Everything is read from the run through :func:`filter_output`, the one adapter between
:class:`~navreplay.filters.result.RunResult` and the exports and the report.

The package, one module per concept: :mod:`~navreplay.export.output` (the adapter),
:mod:`~navreplay.export.files` (file names, atomic writes), :mod:`~navreplay.export.frames`
(ENU / FLU poses and covariances), :mod:`~navreplay.export.tum`, :mod:`~navreplay.export.columns`
(CSV), :mod:`~navreplay.export.odometry` (the Odometry MCAP), :mod:`~navreplay.export.run`
(:class:`RunExport`, a stage of the pipeline) and :mod:`~navreplay.export.ensemble`.
"""

from navreplay.export.columns import (
    UNKNOWN_UNIT,
    Column,
    csv_blocks,
    csv_header,
    csv_rows,
    csv_text,
    ensemble_columns,
    innovation_columns,
    innovation_rows,
    nis_columns,
    no_updates,
    run_columns,
)
from navreplay.export.ensemble import (
    export_ensemble,
)
from navreplay.export.files import (
    FOXGLOVE_LAYOUT,
    INNOVATIONS,
    MANIFEST,
    ODOMETRY_FILE,
    REFERENCE_LABEL,
    check_targets,
    ensemble_targets,
    file_stem,
    file_stems,
    innovation_file,
    run_targets,
    topic_name,
    write_text,
)
from navreplay.export.frames import (
    BODY_FRAME,
    F_FRD_FLU,
    T_NED_ENU,
    UNKNOWN_VARIANCE,
    WORLD_FRAME,
    LocalFrame,
    Poses,
    reference_poses,
    ros_poses,
)
from navreplay.export.odometry import (
    ODOMETRY_TYPE,
    OdometryWriter,
    encode_odometry,
    odometry_dtype,
)
from navreplay.export.output import (
    NAV_AXES,
    NAV_ROWS,
    FilterOutput,
    filter_output,
    nav_state_names,
)
from navreplay.export.run import (
    RunExport,
)
from navreplay.export.tum import (
    TUM_HEADER,
    tum_blocks,
    tum_lines,
)

__all__ = [
    "BODY_FRAME",
    "Column",
    "FOXGLOVE_LAYOUT",
    "F_FRD_FLU",
    "FilterOutput",
    "INNOVATIONS",
    "LocalFrame",
    "MANIFEST",
    "NAV_AXES",
    "NAV_ROWS",
    "ODOMETRY_FILE",
    "ODOMETRY_TYPE",
    "OdometryWriter",
    "Poses",
    "REFERENCE_LABEL",
    "RunExport",
    "TUM_HEADER",
    "T_NED_ENU",
    "UNKNOWN_UNIT",
    "UNKNOWN_VARIANCE",
    "WORLD_FRAME",
    "check_targets",
    "csv_blocks",
    "csv_header",
    "csv_rows",
    "csv_text",
    "encode_odometry",
    "ensemble_columns",
    "ensemble_targets",
    "export_ensemble",
    "file_stem",
    "file_stems",
    "filter_output",
    "innovation_columns",
    "innovation_file",
    "innovation_rows",
    "nav_state_names",
    "nis_columns",
    "no_updates",
    "odometry_dtype",
    "reference_poses",
    "ros_poses",
    "run_columns",
    "run_targets",
    "topic_name",
    "tum_blocks",
    "tum_lines",
    "write_text",
]
