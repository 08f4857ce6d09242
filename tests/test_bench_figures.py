"""The performance figures of README.md and docs/*.md are those of the committed bench/results (bench/render_docs.py)."""

import importlib.util
import json
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _renderer():
    spec = importlib.util.spec_from_file_location("render_docs", ROOT / "bench" / "render_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


render_docs = _renderer()


def test_every_bench_block_of_the_pages_is_what_the_committed_results_render():
    results = render_docs.Results()
    stale = []
    for page in render_docs.pages():
        text = page.read_text(encoding="utf-8")
        _, changed = render_docs.render(text, results, page.name)
        stale += [f"{page.relative_to(ROOT)}: {name}" for name in changed]
    assert not stale, ("figures differ from bench/results (run `python bench/render_docs.py` after the benchmark): "
                       + ", ".join(stale))
    assert results.used  # the pages do quote benchmark figures


def test_every_renderer_fills_a_block_and_every_block_has_a_renderer():
    found = [match["name"] for page in render_docs.pages()
             for match in render_docs.BLOCK.finditer(page.read_text(encoding="utf-8"))]
    assert sorted(set(found)) == sorted(render_docs.BLOCKS)
    for page in render_docs.pages():  # an opening marker without its closing one would be silently skipped
        text = page.read_text(encoding="utf-8")
        assert text.count("<!-- bench:") == text.count("<!-- /bench:"), page


def test_the_results_the_pages_quote_are_committed():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    results = render_docs.Results()
    for page in render_docs.pages():
        render_docs.render(page.read_text(encoding="utf-8"), results, page.name)
    tracked = subprocess.run(["git", "ls-files", "--", *[str(p.relative_to(ROOT)) for p in sorted(results.used)]],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    missing = sorted(str(p.relative_to(ROOT)) for p in results.used if str(p.relative_to(ROOT)) not in tracked)
    assert not missing, f"bench/results is ignored by git: `git add -f` {' '.join(missing)}"


def test_a_changed_result_changes_the_page(tmp_path):
    shutil.copytree(ROOT / "bench" / "results", tmp_path, dirs_exist_ok=True)
    rows = json.loads((tmp_path / "large_models.json").read_text(encoding="utf-8"))
    for row in rows:
        if row["states"] == 200:
            row["largest_file_bytes"] += 10_000
    (tmp_path / "large_models.json").write_text(json.dumps(rows), encoding="utf-8")
    page = (ROOT / "docs" / "generated-code.md").read_text(encoding="utf-8")
    new, changed = render_docs.render(page, render_docs.Results(tmp_path), "generated-code.md")
    assert changed == ["large_models_sizes"] and new != page
    _, again = render_docs.render(new, render_docs.Results(tmp_path), "generated-code.md")
    assert again == []


def test_an_unknown_block_is_refused():
    with pytest.raises(KeyError, match="unknown bench block 'nonesuch'"):
        render_docs.render("<!-- bench:nonesuch -->1 s<!-- /bench:nonesuch -->", render_docs.Results(), "page.md")
