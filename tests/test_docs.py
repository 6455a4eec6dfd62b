"""The documentation against the tree: links, images, the package listing, the figure script."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # code blocks hold no links
    return [m.group(1) for m in LINK.finditer(text)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_relative_links_and_images_exist(page):
    for target in _links(page):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue  # web address or anchor on the same page
        path = (page.parent / target.split("#")[0]).resolve()
        assert path.exists(), f"{page.name}: link to {target} does not exist"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_images_are_small(page):
    for target in _links(page):
        if target.endswith(".png") and not re.match(r"[a-z]+:", target):
            size = (page.parent / target).stat().st_size
            assert size < 400_000, f"{page.name}: {target} is {size // 1024} KiB"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_pages_name_no_machine_paths(page):
    text = page.read_text()
    for prefix in ("/work/", "/tmp/", "/root/", "/home/"):
        assert prefix not in text, f"{page.name} mentions a path under {prefix}"


def test_architecture_lists_the_package_as_it_is():
    text = (ROOT / "docs" / "architecture.md").read_text()
    block = text.split("$ ls navreplay\n", 1)[1].split("\n\n", 1)[0]
    listed = set(block.split())
    actual = {p.name for p in (ROOT / "navreplay").iterdir()
              if not p.name.startswith((".", "__pycache__"))}
    assert listed == actual
    table = text.split("| module | role |", 1)[1].split("\n\n", 1)[0]
    for name in actual - {"__main__.py"}:
        entry = name if name.endswith(".py") else f"{name}/"
        assert f"| `{entry}` |" in table, f"docs/architecture.md: no row for {entry}"


def test_reproduction_figures_are_embedded():
    text = (ROOT / "docs" / "reproduction.md").read_text()
    for name in ("transfer_alignment_errors", "vector_matching_sweeps", "rpm_aided_ins_errors"):
        assert f"(img/{name}.png)" in text


def test_plots_script_draws_the_vector_matching_figure(tmp_path):
    pytest.importorskip("matplotlib")
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_plots", ROOT / "docs" / "plots.py")
    plots = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(plots)
    from navreplay.reproduce import get

    report = get("vector-matching").run(runs=2, seed=0)
    path = plots.vector_matching(report.figures, tmp_path / "vm.png")
    assert path.read_bytes().startswith(b"\x89PNG")
