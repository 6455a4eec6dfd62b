"""The documentation against the tree: links, images, the package listing, the figure script,
and the references of the code to the method documents in docs/methods/."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
METHODS = ROOT / "docs" / "methods"
SOURCES = sorted(p for d in ("navreplay", "tests", "benchmarks") for p in (ROOT / d).rglob("*.py")
                 if p != Path(__file__).resolve())  # this file names the patterns it looks for
METHOD_REF = re.compile(r"docs/methods/([\w-]+\.md)(?:,? §(\d+(?:\.\d+)?))?")
ERRATUM = re.compile(r"\berrat(?:um|a) (E\d+)\b")


def _links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # code blocks hold no links
    return [m.group(1) for m in LINK.finditer(text)]


def _page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_relative_links_and_images_exist(page):
    for target in _links(page):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue  # web address or anchor on the same page
        path = (page.parent / target.split("#")[0]).resolve()
        assert path.exists(), f"{page.name}: link to {target} does not exist"


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_images_are_small(page):
    for target in _links(page):
        if target.endswith(".png") and not re.match(r"[a-z]+:", target):
            size = (page.parent / target).stat().st_size
            assert size < 400_000, f"{page.name}: {target} is {size // 1024} KiB"


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
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
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_plots", ROOT / "docs" / "plots.py")
    plots = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(plots)
    from navreplay.reproduce import get

    report = get("vector-matching").run(runs=2, seed=0)
    path = plots.vector_matching(report.figures, tmp_path / "vm.png")
    assert path.read_bytes().startswith(b"\x89PNG")


def test_method_documents_are_linked_and_keep_their_numbering():
    reproduction = (ROOT / "docs" / "reproduction.md").read_text()
    readme = (ROOT / "README.md").read_text()
    for name in ("transfer-alignment", "vector-matching", "rpm-aided-ins"):
        text = (METHODS / f"{name}.md").read_text()
        assert f"(methods/{name}.md)" in reproduction
        assert f"(docs/methods/{name}.md)" in readme
        for k in range(1, 8):  # the code cites sections 1-7 and the numbered entries of §7
            assert re.search(rf"^## {k}\. ", text, re.M), f"{name}.md: no section {k}"
        assert re.search(r"^- \*\*E1, ", text, re.M), f"{name}.md: no erratum E1"


def test_method_references_in_the_code_resolve():
    """Every ``docs/methods/<name>.md §N`` in the package, tests and benchmarks names an existing
    document and section, and every erratum En of a module is one of the documents it names."""
    for path in SOURCES:
        text = path.read_text()
        where = path.relative_to(ROOT)
        docs = set()
        for m in METHOD_REF.finditer(text):
            doc = METHODS / m.group(1)
            assert doc.exists(), f"{where}: {m.group(0)} does not exist"
            docs.add(doc)
            if m.group(2):
                heading = re.compile(rf"^#+ {re.escape(m.group(2))}[. ]", re.M)
                assert heading.search(doc.read_text()), f"{where}: no section {m.group(0)}"
        for m in ERRATUM.finditer(text):
            assert docs, f"{where}: {m.group(0)} without a docs/methods/ document to resolve it"
            entry = f"- **{m.group(1)},"
            assert any(entry in d.read_text() or f"- **{m.group(1)}." in d.read_text()
                       for d in docs), f"{where}: {m.group(0)} is in none of {sorted(docs)}"


def test_code_and_docs_refer_to_nothing_outside_the_repository():
    """Wording that points at documents the repository does not hold."""
    outside = re.compile(r"\(seed 00\d\)|\bspec(?:'s)? (?:section|§|\d)|\bspec/[\w-]+\.md|"
                         r"\bspec author|\bseed (?:file|text)\b|\bshared/spec\b")
    for path in [*SOURCES, *PAGES]:
        for m in outside.finditer(path.read_text()):
            raise AssertionError(f"{path.relative_to(ROOT)}: {m.group(0)!r}")
