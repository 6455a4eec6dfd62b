"""Recording I/O: navreplay's bulk CDR path against mcap-ros2-support, measured in one run.

* write: N sensor_msgs/Imu messages, ``write_recording`` vs mcap-ros2-support's ``Writer``
  (the baseline runs on fewer messages, 50k by default, as it is slow; rates are per message);
* read: the same file into numpy columns, ``read_recording`` vs mcap's reader with
  mcap-ros2-support's ``DecoderFactory``;
* memory: peak RSS of writing (and of reading back) a 1-hour, 200 Hz IMU + truth recording, each in
  a fresh interpreter (its own ``VmHWM``, :func:`benchmarks.peak_rss`).

Timings keep the best of ``--repeat`` runs, since the machine may be shared.

    python -m benchmarks.bench_io [--n 200000] [--baseline-n 50000] [--repeat 3] [--skip-rss]
                                  [--rss-seconds 3600]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import peak_rss
from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.io import TOPICS, read_recording, write_recording
from navreplay.io.schemas import SPECS

T0_NS = 1_700_000_000_000_000_000
RATE_HZ = 200


def imu_recording(n: int, seed: int = 0) -> Recording:
    """n IMU samples at 200 Hz with random rates and specific forces."""
    rng = np.random.default_rng(seed)
    t_ns = T0_NS + np.arange(1, n + 1, dtype=np.int64) * (1_000_000_000 // RATE_HZ)
    imu = Stream(
        StreamKind.IMU,
        t_ns,
        {
            "omega_ib_b": rng.normal(0, 0.01, (n, 3)),
            "f_b": rng.normal(0, 0.1, (n, 3)) + [0, 0, -9.8],
        },
        "imu_frd",
    )
    return Recording({StreamKind.IMU: imu}, Metadata(scenario="bench"), T0_NS)


def hour_recording(seed: int = 0, seconds: float = 3600.0) -> Recording:
    """``seconds`` (one hour) at 200 Hz: IMU and truth (with 9 extra truth columns), 720k
    messages each for the hour."""
    n = round(seconds * RATE_HZ)
    rec = imu_recording(n, seed)
    rng = np.random.default_rng(seed + 1)
    t_ns = rec[StreamKind.IMU].t_ns
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    truth = Stream(
        StreamKind.TRUTH,
        t_ns,
        {
            "pos": np.column_stack(
                [0.65 + rng.normal(0, 1e-5, n), 2.2 + rng.normal(0, 1e-5, n), rng.normal(0, 1, n)]
            ),
            "v_n": rng.normal(0, 5, (n, 3)),
            "q_nb": q,
            "gyro_bias": rng.normal(0, 1e-5, (n, 3)),
            "accel_bias": rng.normal(0, 1e-3, (n, 3)),
            "misalignment": rng.normal(0, 1e-3, (n, 3)),
        },
        "ned",
    )
    rec.streams[StreamKind.TRUTH] = truth
    return rec


def _baseline_write(path: Path, rec: Recording) -> None:
    from mcap_ros2.writer import Writer

    imu = rec[StreamKind.IMU]
    message = SPECS[StreamKind.IMU].message
    with open(path, "wb") as f, Writer(f) as writer:
        schema = writer.register_msgdef(message.name, message.schema_text)
        omega, f_b = imu["omega_ib_b"].tolist(), imu["f_b"].tolist()
        for t, w, a in zip(imu.t_ns.tolist(), omega, f_b, strict=True):
            sec, nanosec = divmod(t, 1_000_000_000)
            msg = {
                "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": "imu_frd"},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                "orientation_covariance": [-1.0] + [0.0] * 8,
                "angular_velocity": {"x": w[0], "y": w[1], "z": w[2]},
                "angular_velocity_covariance": [0.0] * 9,
                "linear_acceleration": {"x": a[0], "y": a[1], "z": a[2]},
                "linear_acceleration_covariance": [0.0] * 9,
            }
            writer.write_message(TOPICS[StreamKind.IMU], schema, msg, log_time=t, publish_time=t)


def _baseline_read(path: Path) -> dict[str, np.ndarray]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    t, omega, f_b = [], [], []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, _, msg in reader.iter_decoded_messages(topics=[TOPICS[StreamKind.IMU]]):
            t.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            w, a = msg.angular_velocity, msg.linear_acceleration
            omega.append((w.x, w.y, w.z))
            f_b.append((a.x, a.y, a.z))
    return {"t_ns": np.array(t), "omega_ib_b": np.array(omega), "f_b": np.array(f_b)}


def _payloads(path: Path) -> list[bytes]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [m.data for _, _, m in make_reader(f).iter_messages(log_time_order=False)]


def _best(repeat: int, fn, *args) -> float:  # type: ignore[no-untyped-def]
    """Shortest of ``repeat`` wall-clock runs [s] (the machine may be shared)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn(*args)
        best = min(best, time.perf_counter() - start)
    return best


def _rss_child(mode: str, path: str, seconds: str) -> None:
    """Subprocess entry: print JSON with peak RSS [MiB] before and after the I/O."""
    if mode == "write":
        rec = hour_recording(seconds=float(seconds))
        before = peak_rss()
        start = time.perf_counter()
        write_recording(path, rec, force=True)
    else:
        before = peak_rss()
        start = time.perf_counter()
        rec = read_recording(path)
    seconds = time.perf_counter() - start
    after = peak_rss()
    data = sum(
        s.t_ns.nbytes + sum(c.nbytes for c in s.columns.values()) for s in rec.streams.values()
    )
    print(
        json.dumps(
            {
                "before_mib": before / 2**20,
                "peak_mib": after / 2**20,
                "data_mib": data / 2**20,
                "seconds": seconds,
                "messages": sum(len(s) for s in rec.streams.values()),
            }
        )
    )


def _rss(mode: str, path: Path, seconds: float) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_io", "--rss-child", mode, str(path),
         str(seconds)],
        check=True,
        capture_output=True,
        text=True,
        cwd=Path(__file__).resolve().parent.parent,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None, *, quick: bool = False) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_io")
    # quick: the same paths on a few thousand messages and a 10-second memory run
    parser.add_argument("--n", type=int, default=2_000 if quick else 200_000,
                        help="IMU messages (default 200000)")
    parser.add_argument(
        "--baseline-n",
        type=int,
        default=500 if quick else 50_000,
        help="messages for the (slow) mcap-ros2-support baseline; 0: same as --n (default 50000)",
    )
    parser.add_argument("--repeat", type=int, default=1 if quick else 3,
                        help="runs per timing, best kept")
    parser.add_argument("--skip-rss", action="store_true", help="skip the 1-hour memory runs")
    parser.add_argument("--rss-seconds", type=float, default=10.0 if quick else 3600.0,
                        help="length of the memory runs' recording [s] (default 3600)")
    parser.add_argument("--rss-child", nargs=3, metavar=("MODE", "PATH", "SECONDS"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args([] if argv is None else argv)
    if args.rss_child:
        _rss_child(*args.rss_child)
        return
    n, nb = args.n, args.baseline_n or args.n
    rec, rec_b = imu_recording(n), imu_recording(nb)
    with tempfile.TemporaryDirectory() as tmp:
        ours, theirs = Path(tmp) / "ours.mcap", Path(tmp) / "theirs.mcap"
        ours_b = Path(tmp) / "ours_b.mcap"

        def write_ours() -> None:
            write_recording(ours, rec, force=True)

        w_ours = n / _best(args.repeat, write_ours)
        w_theirs = nb / _best(max(1, args.repeat - 1), _baseline_write, theirs, rec_b)
        print(
            f"write Imu ({n} messages; baseline {nb}): navreplay {w_ours:,.0f} msg/s, "
            f"mcap-ros2-support {w_theirs:,.0f} msg/s: ratio {w_ours / w_theirs:.1f}x "
            f"(target >= 5x: {'met' if w_ours >= 5 * w_theirs else 'NOT met'})"
        )
        write_recording(ours_b, rec_b)
        r_ours = n / _best(args.repeat, read_recording, ours)
        r_theirs = nb / _best(1, _baseline_read, ours_b)
        got, ref = read_recording(ours_b)[StreamKind.IMU], _baseline_read(ours_b)
        same = np.array_equal(got.t_ns, ref["t_ns"]) and all(
            np.array_equal(got[k], ref[k]) for k in ("omega_ib_b", "f_b")
        )
        print(
            f"read+decode Imu into numpy ({n} messages; baseline {nb}): navreplay "
            f"{r_ours:,.0f} msg/s, mcap-ros2-support {r_theirs:,.0f} msg/s: ratio "
            f"{r_ours / r_theirs:.1f}x (target >= 10x: "
            f"{'met' if r_ours >= 10 * r_theirs else 'NOT met'}); identical columns: {same}"
        )
        print(
            f"file size for {nb} Imu: navreplay {ours_b.stat().st_size / 2**20:.1f} MiB, "
            f"mcap-ros2-support {theirs.stat().st_size / 2**20:.1f} MiB; "
            f"message payloads identical: {_payloads(ours_b) == _payloads(theirs)}"
        )
        if args.skip_rss:
            return
        hour = Path(tmp) / "hour.mcap"
        w = _rss("write", hour, args.rss_seconds)
        span = (f"{args.rss_seconds / 3600:g} h" if args.rss_seconds % 3600 == 0
                else f"{args.rss_seconds:g} s")
        print(
            f"write {span} at 200 Hz (IMU + truth, {w['messages']:,.0f} messages, "
            f"{hour.stat().st_size / 2**20:.0f} MiB file) in {w['seconds']:.1f} s: peak RSS "
            f"{w['peak_mib']:.0f} MiB (recording in memory: {w['data_mib']:.0f} MiB of columns, "
            f"process at {w['before_mib']:.0f} MiB before writing)"
        )
        r = _rss("read", hour, args.rss_seconds)
        print(
            f"read the same file in {r['seconds']:.1f} s: peak RSS {r['peak_mib']:.0f} MiB "
            f"({r['data_mib']:.0f} MiB of columns, process at {r['before_mib']:.0f} MiB before)"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
