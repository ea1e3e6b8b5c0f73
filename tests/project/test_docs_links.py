"""The reference pages stay reference: every local link of README.md and docs/ resolves, no page under
docs/ (results pages aside) carries a dated heading, and docs/commands.md names every entry point a user
may run (each module with a ``def main(`` under validation/, scripts/, benchmarks/)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
LINK = re.compile(r"\]\(([^)\s]+)\)")
MONTHS = r"(?:Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]*\.?"
DATE = re.compile(rf"\d{{4}}-\d{{2}}-\d{{2}}|\b\d{{1,2}} {MONTHS}(?: \d{{4}})?\b|\b{MONTHS} \d{{1,2}}\b")


def local_links(text: str) -> list[str]:
    """The links of a markdown text to local files, without their anchors (no URLs, no in-page anchors)."""
    out = []
    for target in LINK.findall(text):
        if "://" in target or target.startswith(("#", "mailto:")):
            continue
        out.append(target.split("#", 1)[0])
    return out


def reference_pages() -> list[Path]:
    return sorted(p for p in DOCS.glob("*.md"))


def dated_headings(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("#") and DATE.search(line)]


def test_local_links_are_found_without_anchors_or_urls():
    assert local_links("[a](docs/x.md) [b](https://h/y.md) [c](y.md#s) [d](#top)") == ["docs/x.md", "y.md"]


def test_every_local_link_of_the_readme_and_docs_resolves():
    pages = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
    broken = [f"{page.relative_to(ROOT)} -> {link}" for page in pages
              for link in local_links(page.read_text(encoding="utf-8"))
              if not (page.parent / link).exists()]
    assert broken == []


def test_the_date_pattern_finds_the_forms_reference_pages_used():
    assert dated_headings("## Measured 2026-11-25, second session\n## Walks\n# x (25 Nov 2026, branch h)\n### Nov 25 run")\
        == ["## Measured 2026-11-25, second session", "# x (25 Nov 2026, branch h)", "### Nov 25 run"]
    assert dated_headings("## One walk at 960x600\n## 32 ms brackets\n## Novel selector 3") == []


def test_no_reference_page_has_a_dated_heading():
    pages = reference_pages()
    assert {p.name for p in pages} >= {"motion.md", "native.md", "blur.md", "verdicts.md", "commands.md", "design.md"}
    found = {p.name: dated_headings(p.read_text(encoding="utf-8")) for p in pages}
    assert {k: v for k, v in found.items() if v} == {}


def test_each_reference_page_that_lost_its_measurements_links_its_results_pages():
    for name, results in {"motion.md": ["motion-2026-11-25.md", "motion-2026-11-26.md"],
                          "native.md": ["native-2026-11-28.md"],
                          "blur.md": ["blur-real-2026-11-25.md", "blur-real-2026-11-26.md"],
                          "verdicts.md": ["verdicts-2026-11-25.md", "verdicts-2026-11-28.md", "verdicts-2026-12-04.md"],
                          "loop.md": ["loop-2026-11-25.md"], "design.md": ["response-table-2026-11-25.md"],
                          "real-data.md": ["real-data-2026-11-25.md", "real-data-2026-11-28.md"]}.items():
        text = (DOCS / name).read_text(encoding="utf-8")
        for page in results:
            assert f"](results/{page})" in text, (name, page)


def entry_point_modules() -> list[str]:
    """Every module with a ``def main(`` under validation/, scripts/, benchmarks/, as its path."""
    return sorted(str(p.relative_to(ROOT)) for top in ("validation", "scripts", "benchmarks")
                  for p in (ROOT / top).rglob("*.py") if "def main(" in p.read_text(encoding="utf-8"))


def named_in(module: str, text: str) -> bool:
    """``scripts/x.py`` by its path; ``validation/a/b.py`` as ``python -m validation.a.b``, a package's
    ``cli.py`` or ``__init__.py`` as ``python -m validation.a``."""
    if not module.startswith("validation/"):
        return f"python {module}" in text
    dotted = module[:-3].replace("/", ".")
    if dotted.endswith((".cli", ".__init__")):
        dotted = dotted.rsplit(".", 1)[0]
    return re.search(rf"python -m {re.escape(dotted)}(?![\w.])", text) is not None


def test_commands_page_names_every_entry_point():
    text = (DOCS / "commands.md").read_text(encoding="utf-8")
    modules = entry_point_modules()
    assert len(modules) >= 30 and "scripts/native_terms.py" in modules
    assert [m for m in modules if not named_in(m, text)] == []


def test_named_in_sees_a_missing_entry_point():
    assert named_in("validation/live/cli.py", "`python -m validation.live -o OUT`")
    assert not named_in("validation/live/monte_carlo.py", "`python -m validation.live -o OUT`")
    assert not named_in("benchmarks/bench_save.py", "python benchmarks/bench_demo.py")
