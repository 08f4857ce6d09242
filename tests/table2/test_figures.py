"""The Fig 2-7 analogues overlay the paper's 4-h values and explain coinciding curves (modelgen.table2.figures)."""

import numpy as np
import pytest

from modelgen.table2.figures import (
    FIGURES,
    coinciding_pairs,
    design_difference,
    figure_captions,
    relative_difference,
    write_figures,
)
from modelgen.table2.suboptimal import PAPER_FILTERS
from modelgen.table2.systems import SystemResult
from modelgen.table2.comparison import load_paper_table

TIMES_H = np.linspace(0.0, 4.0, 241)


def _result(key: str, series: np.ndarray) -> SystemResult:
    return SystemResult(key, key.upper(), 3, ("x",), np.zeros((TIMES_H.size, 1, 1)), {"attitude_error_north": series})


def test_relative_difference_ignores_the_first_hour_transient():
    a = np.ones_like(TIMES_H)
    b = a.copy()
    b[TIMES_H < 1.0] = 5.0  # large only while settling
    b[-1] = 1.03
    median, largest = relative_difference(a, b, TIMES_H)
    assert median == 0.0
    assert largest == pytest.approx(0.03)


def test_coinciding_pairs_names_curves_within_one_percent_and_no_others():
    base = 25.0 + np.exp(-TIMES_H)
    results = {
        "optimal": _result("optimal", base),
        "suboptimal_2": _result("suboptimal_2", base * 1.002),
        "suboptimal_1": _result("suboptimal_1", base * 1.4),
    }
    pairs = coinciding_pairs(results, TIMES_H, "attitude_error_north")
    assert [(a, b) for a, b, _, _ in pairs] == [("optimal", "suboptimal_2")]
    assert pairs[0][2] == pytest.approx(0.002)


def test_design_difference_says_when_only_the_gain_schedule_differs():
    designs = {d.key: d for d in PAPER_FILTERS}
    assert "only in the gain schedule" in design_difference(designs["suboptimal_1"], designs["suboptimal_3"])
    assert "every 1 vs every 6 steps" in design_difference(designs["optimal"], designs["suboptimal_2"])
    assert "white states" in design_difference(designs["optimal"], designs["suboptimal_1"])


def _paper_like_results():
    """Six systems whose curves put II on optimal and III on I, as the paper's designs do."""
    keys = ("attitude_error_north", "attitude_error_east", "heading_error", "velocity_error_north",
            "velocity_error_east", "position_cep", "position_error_north", "position_error_east")
    systems = ["optimal", "suboptimal_1", "suboptimal_2", "suboptimal_3", "suboptimal_4", "pure_inertial"]
    results = {}
    for i, key in enumerate(systems):
        scale = {"suboptimal_2": 0.0, "suboptimal_3": 1.0}.get(key, float(i))  # II on optimal, III on I
        errors = {k: 10.0 + scale + np.exp(-TIMES_H) for k in keys}
        results[key] = SystemResult(key, key, 18, ("x",), np.zeros((TIMES_H.size, 1, 1)), errors)
    return results


def test_figures_carry_the_paper_markers_and_no_footnotes(tmp_path, monkeypatch):
    import modelgen.table2.figures as figures

    markers, texts = [], []
    real_markers, real_save = figures._paper_markers, figures._save

    def spy(ax, results, times_h, key, paper, colours):
        markers.extend((s, key) for s in results if paper is not None and key in paper.values.get(s, {}))
        return real_markers(ax, results, times_h, key, paper, colours)

    monkeypatch.setattr(figures, "_paper_markers", spy)
    monkeypatch.setattr(figures, "_save", lambda fig, path: (texts.append(len(fig.texts)), real_save(fig, path))[1])
    paths = write_figures(_paper_like_results(), TIMES_H, tmp_path, paper=load_paper_table(), designs=PAPER_FILTERS)
    assert [p.name[:4] for p in paths] == ["fig2", "fig3", "fig4", "fig5", "fig6", "fig7"]
    assert all(p.stat().st_size > 10_000 for p in paths)
    assert ("pure_inertial", "heading_error") in markers and ("suboptimal_4", "position_cep") in markers
    assert texts == [0] * 6  # the captions are lines of the report, not footnotes taking half a figure


def test_captions_name_coinciding_filters_and_mention_markers_only_where_drawn():
    captions = figure_captions(_paper_like_results(), TIMES_H, paper=load_paper_table(), designs=PAPER_FILTERS)
    assert list(captions) == [name for name, *_ in FIGURES]
    assert all("\n" not in caption and caption.endswith(".") for caption in captions.values())
    fig4 = captions["fig4_integrated_attitude.png"]
    assert "suboptimal_2 lies on optimal (same filter model, another gain schedule" in fig4
    assert "suboptimal_3 lies on suboptimal_1" in fig4 and "diamonds: the paper's 4-h values (Table 2)" in fig4
    # the paper prints no heading error for the integrated systems: Fig 5 draws no marker and says so
    assert "diamonds" not in captions["fig5_integrated_heading.png"]
    assert "no marker is drawn" in captions["fig5_integrated_heading.png"]
    assert "Table 2 and the text of section 3" in captions["fig2_pure_inertial_attitude.png"]
