"""What the view draws and the ranges its panes open on: min/max envelopes that keep every
peak, a bounded number of rows per second, readable y ranges (a minimum span, the start-up
left out where it flattens the result, room for the legend), the run's time span, units and
names read back from the blueprint."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr
from rrd import read_rrd, scalars
from test_viz import log_runs, make_result, make_truth, read_blueprint

from navreplay.viz import naming, open_sink
from navreplay.viz.ranges import (
    DRAWN_RATE_HZ,
    LEGEND_ENTRY,
    Envelope,
    add_rows,
    envelope_rows,
    envelope_rows_of,
    time_range,
    y_range,
)
from navreplay.viz.style import TRUTH_COLOR, TRUTH_COMPONENT_COLORS


def blueprint_fields(path) -> dict[str, dict[str, list]]:
    """Per view name, every field of its blueprint entities (ScalarAxis:range, TimeAxis:...)."""
    reader = rr.chunk.RrdReader(path)
    store = reader.stream(store=reader.blueprints()[0]).collect()
    fields: dict[str, dict[str, list]] = {}
    for chunk in store.stream().to_chunks():
        rb = chunk.to_record_batch()
        key = "/".join(chunk.entity_path.strip("/").split("/")[:2])
        for name in rb.schema.names:
            if ":" in name:
                fields.setdefault(key, {})[name] = rb.column(name).to_pylist()[-1]
    return {f["ViewBlueprint:display_name"][0]: f for f in fields.values()
            if "ViewBlueprint:display_name" in f}


def test_envelope_keeps_every_peak_in_a_bounded_number_of_rows():
    rng = np.random.default_rng(7)
    t = np.arange(360_000) * 0.01  # 1 h at 100 Hz
    v = np.cumsum(rng.normal(size=(t.shape[0], 3)), axis=0)
    spikes = rng.choice(t.shape[0], 25, replace=False)
    v[spikes, 0] += 1e4  # one-sample peaks
    v[1000:1500, 0] = np.nan  # a gap
    k = envelope_rows(t, v, 1.0, columns=(0, 1), maxima=(2,))
    # two columns x (min, max) and a maximum per 1 s bin, a gap's ends
    assert k.shape[0] <= 5 * 3600 + 4
    bins = np.floor(t).astype(int)
    full_max = np.full(3600, -np.inf)
    np.fmax.at(full_max, bins, v[:, 2])
    drawn_max = np.full(3600, -np.inf)
    np.fmax.at(drawn_max, bins[k], v[k, 2])
    np.testing.assert_array_equal(drawn_max, full_max)
    assert set(spikes) <= set(k.tolist())
    bins = np.floor(t).astype(int)
    for j in (0, 1):  # every bin's extremes of the enveloped columns are drawn
        full_max = np.full(3600, -np.inf)
        np.fmax.at(full_max, bins, v[:, j])
        drawn_max = np.full(3600, -np.inf)
        np.fmax.at(drawn_max, bins[k], v[k, j])
        np.testing.assert_array_equal(drawn_max, full_max)
        full_min = np.full(3600, np.inf)
        np.fmin.at(full_min, bins, v[:, j])
        drawn_min = np.full(3600, np.inf)
        np.fmin.at(drawn_min, bins[k], v[k, j])
        np.testing.assert_array_equal(drawn_min, full_min)
    assert np.isnan(v[k, 0]).any(), "the gap stays a gap"


def test_sink_draws_envelopes_with_the_peaks_and_scores_are_untouched(tmp_path):
    truth = make_truth(duration=300.0)
    r = make_result("f", 3, truth, m=3000)
    spike = 1234
    r.x[spike, 12] = 0.5  # a peak of db_g_x
    drawn, full = tmp_path / "drawn.rrd", tmp_path / "full.rrd"
    with open_sink(drawn) as sink:
        assert sink.drawn_rate == DRAWN_RATE_HZ
        log_runs(sink, [r], truth)
    with open_sink(full, drawn_rate=None) as sink:
        log_runs(sink, [r], truth)
    d, f = read_rrd(drawn), read_rrd(full)
    assert drawn.stat().st_size < 0.6 * full.stat().st_size
    for path in ("/f/state/db_g_x", "/f/error/db_g_x", "/f/error/p_N", "/compare/pos_h/f"):
        a, b = scalars(d, path), scalars(f, path)
        assert a.shape[0] < 0.7 * b.shape[0], path
        # the value's peaks both ways; the ±3σ bounds at their widest
        assert np.nanmax(a[:, 0]) == np.nanmax(b[:, 0]) and np.nanmin(a[:, 0]) == np.nanmin(b[:, 0])
        if b.shape[1] == 3:
            assert np.nanmax(a[:, 1]) == np.nanmax(b[:, 1])
            assert np.nanmin(a[:, 2]) == np.nanmin(b[:, 2])
    t = d["/f/state/db_g_x"]["time"]
    assert int(np.rint(r.t[spike] * 1e9)) in t.tolist()
    # a band of constant bounds: a row per bin
    assert d["/f/nees/band"]["time"].shape[0] <= 300.0 * DRAWN_RATE_HZ + 2


def test_y_range_minimum_span_transient_and_legend():
    t = np.arange(0.0, 600.0, 0.1)
    zero = Envelope()
    zero.add(t, np.zeros((t.shape[0], 1)))
    r = y_range([zero])
    assert (r.lo, r.hi) == (-1.0, 1.0) and not r.settled
    const = Envelope()
    const.add(t, np.full((t.shape[0], 1), 50.0))
    r = y_range([const])
    assert r.lo < 50.0 < r.hi and r.hi - r.lo == pytest.approx(10.0)
    # transfer alignment: a 380 mrad start-up, then 1-3 mrad
    ta = Envelope()
    ta.add(t, (2.0 + np.sin(t) + 378.0 * np.exp(-t / 10.0))[:, None])
    r = y_range([ta])
    assert r.settled and r.hi < 5.0 and r.lo > 0.5
    high = Envelope()
    high.add(t, np.full((t.shape[0], 1), 300.0))
    plain = y_range([high, ta])
    assert plain.hi > 370.0 and not plain.settled  # the start-up is not what sets the span
    for entries in (1, 2, 6):  # room above the data for the legend, by its entries
        with_legend = y_range([ta], legend=entries)
        assert with_legend.lo == r.lo
        room = (with_legend.hi - r.hi) / (with_legend.hi - with_legend.lo)
        assert room >= LEGEND_ENTRY * entries
    lo, hi = time_range(0.0, 600.0)
    assert lo < 0.0 and hi > 620.0
    lo, hi = time_range(0.0, 480.0)  # +1m ticks too dense in a narrow pane: up to +10m
    assert lo < 0.0 and hi > 600.0
    assert time_range(0.0, 240.0)[1] < 260.0  # +0s .. +4m labelled: the run's own span


def test_blueprint_ranges_units_and_truth_names(tmp_path):
    truth = make_truth(duration=200.0)
    a = make_result("gps-ins", 1, truth, m=2000)
    b = make_result("gps-ins[gps_pos_sigma_scale=2]", 2, truth, m=2000)
    a.x[:, 3] = 0.0  # a state feedback keeps at zero: no pane
    path = tmp_path / "run.rrd"
    with open_sink(path) as sink:
        log_runs(sink, [a, b], truth)
        t = np.arange(0.0, 200.0, 0.5)
        sink.log_ensemble("TA heading error RMS", t,
                          {"ta RMS": 2.0 + 300.0 * np.exp(-t / 5.0)}, unit="mrad")
        sink.log_ensemble("always zero", t, {"ta RMS": np.zeros_like(t)}, unit="m")
    tabs, views = read_blueprint(path)
    fields = blueprint_fields(path)
    for name, (kind, _) in views.items():
        if kind != "TimeSeries":
            continue
        lo, hi = fields[name]["ScalarAxis:range"][0]
        assert hi > lo, name  # never a lone tick
        start_end = fields[name]["TimeAxis:view_range"][0]
        assert start_end["start"] < 0 and start_end["end"] > 200e9, name
    assert fields["always zero [m]"]["ScalarAxis:range"][0] == [-1.0, 1.0]
    ta = [n for n in views if n.startswith("TA heading error RMS [mrad]")]
    assert ta == ["TA heading error RMS [mrad] (y: after start-up)"]
    assert fields[ta[0]]["ScalarAxis:range"][0][1] < 10.0
    # truth components named like the estimates, in colours told apart
    data = read_rrd(path)
    style = data["static"]["/truth/extra/gyro_bias_eff"].to_pydict()
    # (static: the last style logged is the one shown)
    assert style["SeriesLines:names"][-1] == [f"db_g_{c} (truth)" for c in "xyz"]
    colors = [((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255)
              for c in style["SeriesLines:colors"][-1]]
    assert colors == list(TRUTH_COMPONENT_COLORS) and TRUTH_COLOR not in colors
    # a variant's legend entry is short, its pane titles keep the whole label
    legend = data["static"][naming.entity_path("compare", "pos_h", b.label)].to_pydict()
    assert legend["SeriesLines:names"][0] == ["gps-ins[scale=2]"]
    assert f"{b.label}: position N error [m], ±3σ" in tabs["Position"]


def test_ensemble_misalignments_in_degrees():
    assert naming.resolve_unit("m_a_xy").label == "deg"
    assert naming.resolve_unit("m_g_zx").label == "deg"
    assert naming.quantity_of("m_a_yz") is naming.Tab.SENSOR
    assert naming.resolve_unit("s_a_x").label == "-"


def test_trajectory_and_map_have_a_legend_and_a_scale(tmp_path):
    from navreplay.viz.world import scale_length

    truth = make_truth(duration=200.0)
    a = make_result("gps-ins", 1, truth, m=2000)
    path = tmp_path / "run.rrd"
    with open_sink(path) as sink:
        log_runs(sink, [a], truth)
    tabs, views = read_blueprint(path)
    fields = blueprint_fields(path)
    assert "legend" in tabs["Trajectory"] and "legend" in tabs["Map"]
    assert views["legend"][0] == "2D"
    data = read_rrd(path)
    legend = data["static"]["/legend"].to_pydict()
    # the truth moves 4 m/s north for 200 s: 800 m, a 100 m bar and grid
    assert scale_length(800.0) == 100.0
    assert legend["Points2D:labels"][-1] == ["truth", "gps-ins", "white bar: 100 m"]
    top = [n for n in tabs["Trajectory"] if n.startswith("top-down")]
    assert top == ["top-down N/E [m] (north up), grid 100 m"]
    assert fields[top[0]]["LineGrid3D:spacing"] == [100.0]
    bar = data["static"]["/world/scale"].to_pydict()["LineStrips3D:strips"][-1][0]
    assert np.hypot(*np.subtract(bar[1], bar[0])[:2]) == pytest.approx(100.0)
    assert "/map/scale" in data["static"]
    # the body axes carry no x/y/z badges (they piled up where the tracks meet)
    assert "Arrows3D:labels" not in data["static"]["/world/gps-ins/body/axes"].to_pydict()
    # the viewer opens at the end of the run: the time panel follows the last time
    reader = rr.chunk.RrdReader(path)
    store = reader.stream(store=reader.blueprints()[0]).collect()
    for chunk in store.stream().to_chunks():
        rb = chunk.to_record_batch()
        if (chunk.entity_path == "/time_panel"
                and "TimePanelBlueprint:play_state" in rb.schema.names):
            assert rb.column("TimePanelBlueprint:play_state").to_pylist()[-1] == [3]  # following


def test_every_range_holds_two_labelled_ticks():
    from navreplay.viz.ranges import LABELLED_INTERVALS, labelled

    rng = np.random.default_rng(11)
    for _ in range(2000):
        centre = rng.normal() * 10.0 ** rng.uniform(-6, 4)
        half = 10.0 ** rng.uniform(-6, 4)
        lo, hi = labelled(centre - half, centre + half)
        assert lo <= centre - half and hi >= centre + half  # only ever grown
        step = 10.0 ** np.ceil(np.log10((hi - lo) / LABELLED_INTERVALS))
        ticks = np.floor(hi / step + 1e-6) - np.ceil(lo / step - 1e-6) + 1
        assert ticks >= 2, (lo, hi)
        assert (hi - lo) <= 3.0 * 2 * half  # never flattened below a third of the pane


def test_a_sweep_is_a_bar_chart_on_its_own_axis(tmp_path):
    a_mg = np.array([0.0, 100.0, 200.0, 400.0])
    path = tmp_path / "sweep.rrd"
    with open_sink(path) as sink:
        sink.log_sweep("fig1 N sweep: RMS roll at 10 s", a_mg,
                       {"gravity": np.array([0.1, 0.2, 0.4, 0.8]),
                        "specific_force": np.array([0.1, 0.1, 0.1, 0.1])},
                       unit="deg", x_name="acceleration", x_unit="mg", tab="sweeps",
                       tab_title="Sweeps")
    tabs, views = read_blueprint(path)
    title = "fig1 N sweep: RMS roll at 10 s [deg] vs acceleration [mg]"
    assert tabs["Sweeps"] == [title] and views[title][0] == "BarChart"
    data = read_rrd(path)
    root = naming.entity_path("ensemble", "fig1 N sweep: RMS roll at 10 s")
    bars = {k: data["static"][f"{root}/{k}"].to_pydict() for k in ("gravity", "specific_force")}
    x = {k: np.array(b["BarChart:abscissa"][-1][0]["buffer"]) for k, b in bars.items()}
    width = {k: np.array(b["BarChart:widths"][-1]) for k, b in bars.items()}
    # a bar per model side by side about each acceleration [mg], together 80 % of the spacing
    np.testing.assert_allclose(x["gravity"], a_mg - 20.0)
    np.testing.assert_allclose(x["specific_force"], a_mg + 20.0)
    np.testing.assert_allclose(width["gravity"], 40.0)
    np.testing.assert_allclose(bars["gravity"]["BarChart:values"][-1][0]["buffer"],
                               [0.1, 0.2, 0.4, 0.8])


def _lexsort_rows(t, values, rate_hz, columns=None, maxima=()):
    """The straightforward envelope: per bin, the first row of the sorted values."""
    M = t.shape[0]
    bins = np.floor(t * rate_hz)
    starts = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
    if M <= 2 or starts.shape[0] * 3 >= M:
        return np.arange(M)
    seg = np.repeat(np.arange(starts.shape[0]), np.diff(np.r_[starts, M]))
    keep = np.zeros(M, dtype=bool)
    cols = range(values.shape[1]) if columns is None else columns
    for j, signs in [*((j, (1.0, -1.0)) for j in cols), *((j, (-1.0,)) for j in maxima)]:
        v = values[:, j]
        for sign in signs:
            first = np.lexsort((sign * v, seg))[starts]
            keep[first[np.isfinite(v[first])]] = True
    gap = np.isnan(values[:, 0])
    if gap.any():
        keep[np.flatnonzero(gap & np.r_[True, ~gap[:-1]])] = True
        keep[np.flatnonzero(gap[:-1] & ~gap[1:]) + 1] = True
    return np.flatnonzero(keep)


@pytest.mark.parametrize("seed", range(6))
def test_envelope_rows_are_those_of_the_sorted_bins(seed):
    """The envelope's rows (per-bin extremes found by reduction) are those a sort of each bin
    finds: ties (the first row), +-0, infinities, NaN gaps and all-NaN bins included."""
    rng = np.random.default_rng(seed)
    M = int(rng.integers(50, 3000))
    t = np.sort(rng.uniform(0.0, 60.0, M))
    v = rng.integers(-3, 4, (M, 3)).astype(float)  # many ties
    v[rng.random((M, 3)) < 0.05] = np.nan
    v[rng.random((M, 3)) < 0.02] = np.inf
    v[rng.random((M, 3)) < 0.02] = -np.inf
    v[rng.random((M, 3)) < 0.05] = -0.0
    v[(t > 20.0) & (t < 27.0), 0] = np.nan  # whole bins without a value
    v = np.column_stack([v, np.full(M, np.nan)])  # a column without any
    for columns, maxima in ((None, ()), ((0,), (1,)), ((0, 2), ()), ((3,), (3,))):
        for rate in (0.5, 2.0):
            got = envelope_rows(t, v, rate, columns, maxima)
            np.testing.assert_array_equal(got, _lexsort_rows(t, v, rate, columns, maxima))


def test_envelope_extent_is_that_of_the_finite_values():
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0.0, 900.0, 5000))
    v = rng.standard_normal((5000, 2))
    v[rng.random((5000, 2)) < 0.1] = np.nan
    v[rng.random((5000, 2)) < 0.05] = np.inf
    env = Envelope()
    for a in range(0, 5000, 700):
        env.add(t[a:a + 700], v[a:a + 700])
    finite = np.where(np.isfinite(v), v, np.nan)
    for after in (-np.inf, 300.0):
        sel = t >= after + env.width  # bins that start after `after` hold these rows
        lo, hi = env.extent(after)
        assert lo <= np.nanmin(finite[sel]) and hi >= np.nanmax(finite[sel])
    assert env.extent() == (np.nanmin(finite), np.nanmax(finite))


def _series(rng, M):
    """Series of 1 to 4 columns: many ties, +-0, infinities, NaN gaps, all-NaN bins."""
    out = []
    for k in (1, 3, 1, 4, 2):
        v = rng.integers(-3, 4, (M, k)).astype(float)
        v[rng.random((M, k)) < 0.05] = np.nan
        v[rng.random((M, k)) < 0.02] = np.inf
        v[rng.random((M, k)) < 0.02] = -np.inf
        v[rng.random((M, k)) < 0.05] = -0.0
        out.append(v)
    out[2][M // 3:M // 2, 0] = np.nan  # whole bins without a value
    out.append(rng.standard_normal((M, 2)))  # finite everywhere
    return out


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("regular", [True, False])
def test_envelope_rows_of_several_series_are_those_of_each(seed, regular):
    """Drawn together (bins of as many rows each, as a steady output rate gives, or uneven
    ones), the rows of each series are those of a call per series."""
    rng = np.random.default_rng(seed)
    M = int(rng.integers(200, 3000))
    t = (np.arange(M) * 0.1 if regular else np.sort(rng.uniform(0.0, 60.0, M)))
    series = _series(rng, M)
    ways = [(None, ()), ((0,), (1,)), ((0,), ()), ((0, 3), (1,)), ((1,), ()), (None, (0,))]
    drawn = [(v, *ways[i % len(ways)]) for i, v in enumerate(series)]
    drawn = [(v, c, m) for v, c, m in drawn
             if all(j < v.shape[1] for j in (*(c or ()), *m))]
    for rate in (0.5, 2.0):
        got = envelope_rows_of(t, drawn, rate)
        for (v, c, m), k in zip(drawn, got, strict=True):
            want = envelope_rows(t, v, rate, c, m)
            np.testing.assert_array_equal(np.arange(M) if k is None else k, want)
    assert envelope_rows_of(t[:2], drawn, 0.5) == [None] * len(drawn)


@pytest.mark.parametrize("seed", range(3))
def test_envelopes_added_together_are_those_added_one_by_one(seed):
    rng = np.random.default_rng(seed)
    M = 4000
    t = np.sort(rng.uniform(0.0, 900.0, M))
    series = _series(rng, M)
    one, together = [Envelope() for _ in series], [Envelope() for _ in series]
    for a in range(0, M, 700):
        for e, v in zip(one, series, strict=True):
            e.add(t[a:a + 700], v[a:a + 700])
        add_rows(together, t[a:a + 700], [v[a:a + 700] for v in series])
    for e, f in zip(one, together, strict=True):
        assert (e.width, e.t_first, e.t_last) == (f.width, f.t_first, f.t_last)
        np.testing.assert_array_equal(e.lo, f.lo)
        np.testing.assert_array_equal(e.hi, f.hi)
