"""The parked vehicle of ``bench_memory --parked``: written in pieces into one recording that
reads back continuous, with the physics of a vehicle at rest (gravity and the earth's rate
sensed through the IMU's bias), and replayed by gps-ins like the drive it stands in for."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from benchmarks import bench_memory
from navreplay.core.streams import StreamKind
from navreplay.geo.earth import gravity_n, omega_ie_n
from navreplay.geo.rotations import quat_to_dcm
from navreplay.io import read_recording
from navreplay.replay import FilterSpec
from navreplay.viz.options import VizMode, VizOptions

run_job = importlib.import_module("navreplay.jobs.run")


@pytest.fixture(scope="module")
def parked_file(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(bench_memory, "PIECE_S", 20.0)  # 72 s in four pieces
        return bench_memory.parked_recording(0.02, tmp_path_factory.mktemp("parked"))


@pytest.fixture(scope="module")
def parked(parked_file):
    return read_recording(parked_file)


def test_the_pieces_join_into_one_continuous_recording(parked) -> None:
    imu, truth = parked[StreamKind.IMU], parked[StreamKind.TRUTH]
    assert len(imu) == 7200 and len(truth) == 7201 and len(parked[StreamKind.GPS]) == 73
    assert len(parked[StreamKind.MAG]) == 721
    for kind in (StreamKind.IMU, StreamKind.TRUTH, StreamKind.GPS, StreamKind.MAG):
        step = np.diff(parked[kind].t_ns)
        assert step.min() == step.max(), kind  # no gap or repeat where the pieces meet
    assert int(imu.t_ns[0] - parked.t0_ns) == 10_000_000
    assert parked.metadata.params["duration"] == pytest.approx(72.0)


def test_the_imu_senses_gravity_and_the_earth_rate_at_rest(parked) -> None:
    truth = parked[StreamKind.TRUTH]
    assert np.ptp(truth["pos"], axis=0).max() == 0.0 and np.abs(truth["v_n"]).max() == 0.0
    lat, _, h = truth["pos"][0]
    C_bn = quat_to_dcm(truth["q_nb"][0]).T
    imu, n = parked[StreamKind.IMU], len(parked[StreamKind.IMU])
    spec = parked.metadata.sensors["imu"]
    f = C_bn @ -gravity_n(lat, h) + truth["accel_bias"][0]
    w = C_bn @ omega_ie_n(lat) + truth["gyro_bias"][0]
    # the means are within 4 sigma of white noise at the grade's VRW and ARW (100 Hz)
    np.testing.assert_allclose(imu["f_b"].mean(axis=0), f,
                               atol=4 * spec["accel_vrw"] * np.sqrt(100.0 / n))
    np.testing.assert_allclose(imu["omega_ib_b"].mean(axis=0), w,
                               atol=4 * spec["gyro_arw"] * np.sqrt(100.0 / n))
    assert np.linalg.norm(f) == pytest.approx(9.80, abs=0.01)


def test_gps_ins_replays_the_parked_vehicle(parked_file) -> None:
    job = run_job.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(parked_file,),
                         viz=VizOptions(mode=VizMode.NONE))
    summary = run_job.run(job).summary["filters"]["gps-ins"]
    assert summary["pos_rms_h"] < 2.0  # 2.5 m fixes, averaged at rest
    assert summary["vel_rms"] < 0.1
    assert 0.5 < summary["nees_mean"] / summary["nees_dof"] < 1.5, summary["nees_mean"]
