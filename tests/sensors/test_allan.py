"""`navreplay allan`: the Allan deviation of a still IMU, the noise terms fitted to it, the
specification it writes, and the segments it refuses.

Recovery of the simulated grades: the default suite fits a 2 h consumer-grade recording (the
grade whose hump a short record resolves); the slow suite fits every grade at 2-4 h over
several seeds (and the navigation grade, whose one-hour correlation time a 4 h record cannot
resolve, at 24 h). The seeds are not those the fit's choices were made on (100-109).
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest
from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.core.streams import Stream
from navreplay.io import read_recording, write_recording
from navreplay.sensors import allan
from navreplay.sensors.allan import NoiseFit, Term, analyse_triad, fit_noise, gm_avar
from navreplay.sensors.imu import imu_grade
from navreplay.sensors.specs import SensorSpecs
from navreplay.sim.scenario import simulate


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(res) -> str:
    """The error line (the reader may have warned before it, e.g. of a gap)."""
    assert res.exit_code == 1, res.output
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert all(line.startswith("warning: ") for line in lines[:-1]), res.output
    assert lines[-1].startswith("Error: "), res.output
    return lines[-1]


# --------------------------------------------------------------------------------------------
# the model's Allan variance


def test_gauss_markov_adev_peak_and_limits():
    T, sigma = 300.0, 2.0
    tau = np.logspace(-1, 5, 20001) * T / 100
    adev = np.sqrt(gm_avar(tau, sigma, T))
    k = int(np.argmax(adev))
    assert tau[k] / T == pytest.approx(allan.GM_PEAK_X, rel=1e-3)
    assert adev[k] / sigma == pytest.approx(allan.GM_PEAK_ADEV, rel=1e-6)
    # tau << T: a random walk of density sigma sqrt(2/T); tau >> T: white noise sigma sqrt(2T)
    short, long_ = np.array([T * 1e-4]), np.array([T * 1e4])
    assert gm_avar(short, sigma, T)[0] == pytest.approx(2 * sigma**2 / T * short[0] / 3, rel=1e-3)
    assert gm_avar(long_, sigma, T)[0] == pytest.approx(2 * sigma**2 * T / long_[0], rel=1e-3)
    assert allan.FLICKER_FLOOR == pytest.approx(0.6643, abs=1e-4)


def test_fit_recovers_the_terms_of_an_exact_curve():
    """The Allan variance of white noise + a Gauss-Markov bias + a random walk, without
    estimation noise, on the clusters of a 4 h record at 100 Hz: the fit returns its terms."""
    n, rate = 4 * 3600 * 100, 100.0
    truth = NoiseFit(white=2e-3, gm_sigma=2e-4, gm_tau=200.0, walk=5e-6,
                     terms=frozenset(Term), floor=math.nan, floor_tau=math.nan)
    tau = allan.cluster_sizes(n) / rate
    fit, edf = fit_noise(tau, truth.avar(tau), rate, n, axes=3)
    assert fit.terms == frozenset(Term)
    assert fit.white == pytest.approx(truth.white, rel=1e-3)
    assert fit.gm_sigma == pytest.approx(truth.gm_sigma, rel=1e-2)
    assert fit.gm_tau == pytest.approx(truth.gm_tau, rel=2e-2)
    assert fit.walk == pytest.approx(truth.walk, rel=2e-2)
    assert np.all(edf > 0) and edf[0] > 100 * edf[-1]  # short clusters are many
    # the floor is the curve's minimum (here where the random walk takes over)
    fine = np.logspace(-1, math.log10(tau[-1]), 2000)
    k = int(np.argmin(truth.avar(fine)))
    assert fit.floor == pytest.approx(math.sqrt(truth.avar(fine)[k]), rel=1e-3)
    assert fit.floor_tau == pytest.approx(fine[k], rel=0.05)


def test_white_noise_alone_reports_only_white_noise():
    rng = np.random.default_rng(3)
    N = 0.01
    a = analyse_triad(rng.standard_normal((36_000, 3)) * N / math.sqrt(0.1), 10.0, bootstrap=0)
    assert a.fit.terms == {Term.WHITE}
    assert a.fit.white == pytest.approx(N, rel=0.02)
    assert a.fit.gm_sigma == 0.0 and math.isnan(a.fit.gm_tau) and a.fit.walk == 0.0
    assert any("bias instability: not detected" in note for note in a.fit.notes)
    assert a.fit.walk_bound > 0.0 and math.isnan(a.fit.floor)  # the curve falls throughout


def test_random_walk_recovered():
    """White noise + a random walk (2 h at 10 Hz; over 20 seeds K/K_true = 1.00 +- 0.11)."""
    truth = NoiseFit(white=0.01, gm_sigma=0.0, gm_tau=math.nan, walk=2e-4,
                     terms=frozenset({Term.WHITE, Term.RANDOM_WALK}), floor=math.nan,
                     floor_tau=math.nan)
    y = allan.simulate_terms(truth, 72_000, 0.1, np.random.default_rng(7))
    a = analyse_triad(y, 10.0, bootstrap=0)
    assert Term.RANDOM_WALK in a.fit.terms
    assert a.fit.white == pytest.approx(truth.white, rel=0.02)
    assert a.fit.walk == pytest.approx(truth.walk, rel=0.3)


def _check_recovery(grade: str, duration: float, seed: int, rate: float = 100.0,
                    bootstrap: int = 0) -> dict[str, allan.TriadAnalysis]:
    model = imu_grade(grade)
    rec = simulate("stationary", {"duration": duration, "imu_grade": grade, "imu_rate": rate},
                   seed=seed)
    out = {}
    for name, col, white, sigma, tau in (
            ("gyro", "omega_ib_b", model.gyro_arw, model.gyro_bias_instability,
             model.gyro_bias_tau),
            ("accel", "f_b", model.accel_vrw, model.accel_bias_instability,
             model.accel_bias_tau)):
        a = analyse_triad(rec["imu"][col], rate, bootstrap=bootstrap)
        assert a.fit.white == pytest.approx(white, rel=0.10), (grade, name)
        assert Term.GAUSS_MARKOV in a.fit.terms, (grade, name, a.fit.notes)
        assert a.fit.gm_sigma == pytest.approx(sigma, rel=0.30), (grade, name)
        assert 0.5 * tau < a.fit.gm_tau < 2.0 * tau, (grade, name)  # T spreads more: 10-20 %
        out[name] = a
    return out


def test_consumer_grade_recovered_from_2_hours():
    """Spread over 10 seeds (200-209): sigma 1.00 +- 0.05, T 1.00 +- 0.10, N 1.000 +- 0.002."""
    _check_recovery("consumer", 7200.0, seed=1)


def test_bootstrap_intervals_bracket_the_fit():
    rec = simulate("stationary", {"duration": 1800.0, "imu_grade": "consumer"}, seed=2)
    a = analyse_triad(rec["imu"]["f_b"], 100.0, bootstrap=8)
    assert a.bootstrap == 8
    for key in ("white", "gm_sigma", "gm_tau"):
        lo, hi = a.intervals[key]
        assert 0.0 < lo < hi
    lo, hi = a.intervals["white"]
    assert lo < a.fit.white < hi and (hi - lo) / a.fit.white < 0.05


# --------------------------------------------------------------------------------------------
# still or not


def test_motion_detects_a_tilt_and_a_turn():
    rng = np.random.default_rng(0)
    n, rate = 6000, 100.0
    f = np.tile([0.0, 0.0, -9.80665], (n, 1)) + rng.standard_normal((n, 3)) * 1e-3
    w = rng.standard_normal((n, 3)) * 1e-4
    assert allan.motion(f, w, rate) is None
    tilted = f.copy()
    tilted[3000:, 0] += 0.2  # 1.2 deg of tilt after 30 s
    when, what = allan.motion(tilted, w, rate)
    assert 29.0 <= when <= 31.0 and "specific force" in what
    turning = w.copy()
    turning[4000:4500, 2] += math.radians(5.0)  # a 5 deg/s turn for 5 s
    when, what = allan.motion(f, turning, rate)
    assert 39.0 <= when <= 41.0 and "angular rate" in what
    when, what = allan.motion(f / 9.80665, w, rate)  # in g, not m/s^2
    assert when == 0.0 and "not gravity" in what


# --------------------------------------------------------------------------------------------
# the command


@pytest.fixture(scope="module")
def still_30min(tmp_path_factory):
    path = tmp_path_factory.mktemp("allan") / "still.mcap"
    write_recording(path, simulate("stationary", {"duration": 1800.0, "imu_grade": "consumer"},
                                   seed=5))
    return path


def test_allan_command_writes_spec_figure_and_view(still_30min, tmp_path):
    spec, fig, svg, rrd = (tmp_path / n for n in ("imu.toml", "a.png", "a.svg", "a.rrd"))
    res = invoke("allan", still_30min, "-o", spec, "--plot", fig, "--save", rrd,
                 "--bootstrap", "4")
    assert res.exit_code == 0, res.output
    assert "topic /imu" in res.output and "angle random walk [deg/sqrt(h)]" in res.output
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert invoke("allan", still_30min, "--plot", svg, "--bootstrap", "0").exit_code == 0
    assert svg.read_text().lstrip().startswith("<?xml")

    # the specification: the fitted terms, in datasheet units, that navreplay reads back
    table = tomllib.loads(spec.read_text())["sensors"]["imu"]
    assert set(table) == {"gyro_arw", "gyro_bias_instability", "gyro_bias_tau", "accel_vrw",
                          "accel_bias_instability", "accel_bias_tau"}
    assert table["gyro_arw"].endswith("deg/sqrt(h)") and table["accel_vrw"].endswith(
        "ug/sqrt(Hz)")
    arw = float(table["gyro_arw"].split()[0])
    assert arw == pytest.approx(0.4, rel=0.1)  # the consumer grade's 0.4 deg/sqrt(h)

    # simulate --config takes it: the new recording carries the fitted values
    out = tmp_path / "again.mcap"
    res = invoke("simulate", "stationary", "-o", out, "--config", spec, "-p", "duration=20")
    assert res.exit_code == 0, res.output
    specs = SensorSpecs.from_metadata(read_recording(out).metadata.sensors)
    assert math.degrees(specs.imu.gyro_arw) * 60 == pytest.approx(arw, rel=1e-5)
    # run --config takes it too
    res = invoke("run", "ins", out, "--config", spec, "--no-viz")
    assert res.exit_code == 0, res.output

    # the Rerun view: one 2D log-log view per triad and the report
    from rerun.chunk import RrdReader

    chunks = {c.entity_path: c.to_record_batch()
              for c in RrdReader(rrd).stream().collect().stream().to_chunks()}
    for entity in ("/allan/gyro/triad", "/allan/gyro/axis/x", "/allan/accel/fit",
                   "/allan/accel/term/0", "/allan/gyro/grid", "/allan/summary"):
        assert entity in chunks, sorted(chunks)
    strip = np.array(chunks["/allan/gyro/triad"].column("LineStrips2D:strips").to_pylist()[0][0])
    # x = log10(tau): from the sampling interval (10 ms) to half the record
    assert strip[0, 0] == pytest.approx(-2.0) and strip[-1, 0] == pytest.approx(
        math.log10(900.0), abs=0.01)


def test_allan_refuses_motion_with_one_line(tmp_path):
    drive = tmp_path / "drive.mcap"
    write_recording(drive, simulate("vehicle-drive", {"duration": 60.0}, seed=1))
    line = one_line_error(invoke("allan", drive))
    assert str(drive) in line and "topic /imu, t = 0.01 to 60 s" in line
    when = float(line.split("not still at t = ")[1].split()[0])
    assert 10.0 <= when <= 12.0  # the drive pulls away at 10 s
    # the still first 10 s are accepted; they support only the white noise
    spec = tmp_path / "imu.toml"
    res = invoke("allan", drive, "--end", "9.9", "-o", spec, "--bootstrap", "0")
    assert res.exit_code == 0, res.output
    assert set(tomllib.loads(spec.read_text())["sensors"]["imu"]) == {"gyro_arw", "accel_vrw"}
    assert "bias instability: not detected" in res.output


def test_allan_refuses_short_empty_and_gappy_segments(still_30min, tmp_path):
    line = one_line_error(invoke("allan", still_30min, "--end", "1.5"))
    assert "topic /imu, t = 0.01 to 1.5 s" in line and "too short" in line
    line = one_line_error(invoke("allan", still_30min, "--start", "5000"))
    assert "no IMU samples" in line and "the topic covers t = 0.01 to 1800 s" in line
    line = one_line_error(invoke("allan", still_30min, "--start", "20", "--end", "10"))
    assert "is not before --end" in line
    rec = simulate("stationary", {"duration": 120.0}, seed=1)
    imu = rec["imu"]
    keep = np.ones(len(imu.t_ns), dtype=bool)
    keep[5000:5300] = False  # 3 s lost at t = 50 s
    rec.streams[imu.kind] = Stream(imu.kind, imu.t_ns[keep],
                                      {k: v[keep] for k, v in imu.columns.items()},
                                      imu.frame_id)
    gappy = tmp_path / "gappy.mcap"
    write_recording(gappy, rec)
    line = one_line_error(invoke("allan", gappy))
    assert "gaps" in line and "t = 50" in line
    assert invoke("allan", gappy, "--start", "55", "--bootstrap", "0").exit_code == 0


def test_allan_plot_suffix_checked_before_work(still_30min):
    res = invoke("allan", still_30min, "--plot", "fig.jpg")
    assert res.exit_code == 2 and ".png or .svg" in res.output


# --------------------------------------------------------------------------------------------
# every grade (slow)


@pytest.mark.slow
@pytest.mark.parametrize(("grade", "duration"), [("consumer", 7200.0), ("mems", 14400.0)])
def test_grades_recovered_from_hours(grade, duration):
    """White noise within 10 % and bias instability within 30 % at 2-4 h (over seeds 200-209
    sigma spreads by 4-7 %)."""
    _check_recovery(grade, duration, seed=11)


def _recovery_over_seeds(grade: str, duration: float, rate: float, seeds) -> None:
    """Where one record leaves the hump barely resolved (over seeds 200-209 sigma spreads by
    10 %, and one tactical gyro in ten shows no hump), the claim is over several records:
    white noise within 10 % in every one, the hump found in at least four of five, and within
    30 % in at least four of those, with a median within 10 %."""
    model = imu_grade(grade)
    ratios = {"gyro": [], "accel": []}
    for seed in seeds:
        rec = simulate("stationary", {"duration": duration, "imu_grade": grade,
                                      "imu_rate": rate}, seed=seed)
        for name, col, white, sigma in (
                ("gyro", "omega_ib_b", model.gyro_arw, model.gyro_bias_instability),
                ("accel", "f_b", model.accel_vrw, model.accel_bias_instability)):
            a = analyse_triad(rec["imu"][col], rate, bootstrap=0)
            assert a.fit.white == pytest.approx(white, rel=0.10), (grade, name, seed)
            if Term.GAUSS_MARKOV in a.fit.terms:
                ratios[name].append(a.fit.gm_sigma / sigma)
    for name, r in ratios.items():
        r = np.array(r)
        assert len(r) >= len(seeds) - 1, (grade, name, r)
        assert np.sum(np.abs(r - 1.0) <= 0.3) >= len(r) - 1, (grade, name, r)
        assert abs(np.median(r) - 1.0) <= 0.10, (grade, name, r)


@pytest.mark.slow
def test_tactical_grade_recovered_from_4_hours():
    _recovery_over_seeds("tactical", 14400.0, 100.0, range(11, 16))


@pytest.mark.slow
def test_navigation_grade_needs_a_day():
    """A one-hour correlation time is not resolved by 4 h (the fit says so and keeps the white
    noise); 24 h at 10 Hz recover it."""
    model = imu_grade("navigation")
    rec = simulate("stationary", {"duration": 14400.0, "imu_grade": "navigation"}, seed=11)
    a = analyse_triad(rec["imu"]["omega_ib_b"], 100.0, bootstrap=0)
    assert a.fit.white == pytest.approx(model.gyro_arw, rel=0.1)
    assert Term.GAUSS_MARKOV not in a.fit.terms
    assert any(note.startswith("bias instability") for note in a.fit.notes)
    _recovery_over_seeds("navigation", 86400.0, 10.0, range(11, 16))
