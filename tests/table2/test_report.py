"""run_covariance_analysis writes Table 2, its CSV and the figures (modelgen.table2.report)."""

from __future__ import annotations

import csv

from modelgen.table2.report import run_covariance_analysis


def test_text_outputs_are_byte_stable_and_list_every_system(tmp_path, paper_systems):
    first = run_covariance_analysis(tmp_path / "a", paper_systems, sensitivity=False, figures=False)
    second = run_covariance_analysis(tmp_path / "b", paper_systems, sensitivity=False, figures=False)
    for name in ("table2.md", "table2.csv"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    for label in ("DI (optimal)", "DI (sub I)", "DI (sub II)", "DI (sub III)", "DI (sub IV)", "I (inertial)"):
        assert label in first.table
    assert "ours/paper" in first.markdown and "Improvement" in first.markdown
    rows = list(csv.DictReader((tmp_path / "a" / "table2.csv").open(encoding="utf-8")))
    cep = {r["system"]: r for r in rows if r["quantity"] == "position_cep"}
    assert len(cep) == 6 and all(r["ours_over_paper"] for r in cep.values())
    assert second.files == [tmp_path / "b" / "table2.md", tmp_path / "b" / "table2.csv"]


def test_figures_2_to_7_are_written_as_png(tmp_path, paper_systems):
    report = run_covariance_analysis(tmp_path, paper_systems, sensitivity=False, figures=True)
    pngs = sorted(p.name for p in report.files if p.suffix == ".png")
    assert [name[:4] for name in pngs] == ["fig2", "fig3", "fig4", "fig5", "fig6", "fig7"]
    for p in report.files:
        if p.suffix == ".png":
            assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
