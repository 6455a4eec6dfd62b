"""Sanity checks of a recording's table of contents, for files whose damage no CRC reveals.

An MCAP file written without CRCs (or with its summary damaged) can carry wrong counts and times
that read without error. :func:`contents_problems` compares what a walk over the file found with
what the file itself claims: the summary's statistics (message counts per channel, first and last
message time) and, for navreplay's own recordings, the metadata (start time and duration). Each
disagreement is one phrase for the ``DAMAGED`` line of ``navreplay info``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

TIME_SLACK_NS = 1_000_000_000
"""Messages may lie this far outside the metadata's [t0, t0 + duration] [ns]."""


def contents_problems(
    counts: Mapping[int, int],
    lo: Mapping[int, int],
    hi: Mapping[int, int],
    topics: Mapping[int, str],
    statistics: Any | None,
    t0_ns: int | None,
    duration_s: float | None,
) -> list[str]:
    """Disagreements between the messages found and the file's own statistics and metadata.

    Parameters
    ----------
    counts, lo, hi : mapping of channel id to int
        Messages found per channel, and their first and last log time [ns].
    topics : mapping of channel id to str
        Topic names, for messages.
    statistics : mcap Statistics or None
        The summary's statistics record (None for a file without one).
    t0_ns : int or None
        Recording start from the metadata.
    duration_s : float or None
        Scenario duration from the metadata [s].
    """
    out: list[str] = []
    if statistics is not None:
        total = sum(counts.values())
        if statistics.message_count != total:
            out.append(f"the summary counts {statistics.message_count} messages, the file holds "
                       f"{total}")
        for cid, n in sorted(statistics.channel_message_counts.items()):
            if counts.get(cid, 0) != n:
                out.append(f"topic {topics.get(cid, cid)}: the summary counts {n} messages, the "
                           f"file holds {counts.get(cid, 0)}")
        if total and statistics.message_count:
            first, last = min(lo.values()), max(hi.values())
            if (first, last) != (statistics.message_start_time, statistics.message_end_time):
                out.append(f"message times {first}..{last} ns differ from the summary's "
                           f"{statistics.message_start_time}..{statistics.message_end_time} ns")
    if t0_ns is not None and duration_s is not None and duration_s > 0:
        end_ns = t0_ns + int(duration_s * 1e9)
        for cid in sorted(lo):
            if lo[cid] < t0_ns - TIME_SLACK_NS or hi[cid] > end_ns + TIME_SLACK_NS:
                out.append(f"topic {topics.get(cid, cid)}: messages at "
                           f"{(lo[cid] - t0_ns) * 1e-9:.3f}..{(hi[cid] - t0_ns) * 1e-9:.3f} s, "
                           f"outside the recording's 0..{duration_s:g} s")
    return out
