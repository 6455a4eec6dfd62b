"""What a job returns and writes: its report and atomically written JSON summaries."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from navreplay.core.streams import jsonable
from navreplay.io.outputs import atomic_path

DEFAULT_OUT = Path("out")
"""Where derived outputs (.rrd, summaries, demo recordings) go by default."""


def write_json(path: Path, data: Any) -> None:
    """Write JSON atomically (NaN and infinities as null)."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(jsonable(data, strict=True), indent=2) + "\n")


@dataclasses.dataclass
class RunReport:
    """Outcome of ``run``, ``montecarlo`` and the demo's replay.

    Attributes
    ----------
    title : str
    table : str
        Summary table(s).
    summary : dict
        JSON-ready figures (what ``--summary`` writes).
    viz : str
        Where the Rerun output went and how to open it ("" for none).
    notes : list[str]
        Further lines (failed runs, timing).
    sink : Any
        The Rerun sink when it must stay alive (``--serve``).
    """

    title: str
    table: str
    summary: dict[str, Any]
    viz: str = ""
    notes: list[str] = dataclasses.field(default_factory=list)
    sink: Any = None

    def format(self) -> str:
        parts = [self.title, "", self.table]
        if self.notes:
            parts += [""] + [n for n in self.notes if n]
        if self.viz:
            parts += ["", self.viz]
        return "\n".join(parts)
