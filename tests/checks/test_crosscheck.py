"""Hand-written models against their twins: every entry equal or explained by declared data, never silently."""

from __future__ import annotations

import dataclasses
import json

import pytest
import sympy as sp

from modelgen.checks import crosscheck as cc
from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel


def twin_of(model: ErrorModel, name: str = "ned_doppler18_test_twin", **dynamics: str) -> ErrorModel:
    """A copy of ``model`` under another name, some equations replaced (a stand-in twin)."""
    equations = {s.name: model.dynamics[s.name] for s in model.states}
    equations.update(dynamics)
    built = ErrorModel.build(
        name=name, states=model.states, noises=model.noises, parameters=model.parameters,
        dynamics=equations, measurements=model.measurements,
    )
    return dataclasses.replace(built, check=model.check)


def pair(**fields) -> cc.Pair:
    return cc.Pair(hand="ned_doppler18", twin="ned_doppler18_test_twin", **fields)


GYRO_SIGN = cc.Convention(
    name="gyro drift sign",
    states=("eps_c_x", "eps_c_y", "eps_c_z", "eps_r_x", "eps_r_y", "eps_r_z"),
    noises=("w_eps_x", "w_eps_y", "w_eps_z"),
    reason="the hand model adds the drift to the attitude rate (drift = true - measured)",
)


def flipped_gyro_twin(model: ErrorModel) -> ErrorModel:
    """The twin a physicist writes: measured rate = true + drift, so the drift enters the attitude error with a minus."""
    changes = {}
    for row in ("alpha", "beta", "gamma"):
        text = sp.sstr(model.dynamics[model.states[model.state_index(row)].name])
        changes[model.states[model.state_index(row)].name] = text.replace("eps_c_", "(-eps_c_").replace("eps_r_", "(-eps_r_") \
            .replace("_x", "_x)").replace("_y", "_y)").replace("_z", "_z)")
    return twin_of(model, **changes)


def test_a_twin_equal_to_the_hand_model_is_equal_everywhere(paper_model, paper_derived):
    result = cc.cross_check(pair(), paper_derived, derive(twin_of(paper_model)))
    assert result.counts()["equal"] == len(result.entries) == 64
    assert result.differences == []


def test_a_declared_sign_convention_explains_the_negated_drift_columns(paper_model, paper_derived):
    twin = derive(twin_of(paper_model, **{
        "attitude_error_north": str(paper_model.dynamics["attitude_error_north"]).replace("c11*", "-c11*").replace("c12*", "-c12*").replace("c13*", "-c13*"),
    }))
    assert twin.F[0, 7] == -paper_derived.F[0, 7]
    result = cc.cross_check(pair(conventions=(GYRO_SIGN,)), paper_derived, twin)
    conventions = [e for e in result.entries if e.status == "convention"]
    assert {(e.row, e.column) for e in conventions} == {("alpha", f"eps_{k}_{a}") for k in "cr" for a in "xyz"}
    assert all("gyro drift sign" in e.reason for e in conventions)
    assert result.unexplained == []
    # without the declaration the same entries are unexplained, with the sign-flip hint
    bare = cc.cross_check(pair(), paper_derived, twin)
    assert len(bare.unexplained) == 6 and all("sign flip" in e.reason for e in bare.unexplained)


def test_a_term_a_declared_approximation_drops_is_named_with_its_size(paper_model, paper_derived):
    twin = derive(twin_of(paper_model))
    i, j = paper_model.state_index("dphi"), paper_model.state_index("dV_n")
    R, h = sp.Symbol("R", real=True), sp.Symbol("V_d", real=True)
    dropped = cc.NeglectedTerm("F", i, j, -h / R**2, "single Earth radius")
    result = cc.cross_check(pair(), paper_derived, twin, [dropped])
    (entry,) = [e for e in result.entries if (e.row, e.column) == ("dphi", "dV_n")]
    assert entry.status == "approximation" and "single Earth radius" in entry.reason
    assert entry.derived == sp.sstr(1 / R - h / R**2)
    assert entry.magnitude == 0.0  # V_d = 0 in the paper's level flight
    assert result.unexplained == []


def test_an_undeclared_difference_is_unexplained_with_hints_until_declared_a_hand_model_error(paper_model, paper_derived):
    twin = derive(twin_of(paper_model, velocity_error_north=str(paper_model.dynamics["velocity_error_north"]) + " - omega_ie*cos(phi)*dV_e"))
    result = cc.cross_check(pair(), paper_derived, twin)
    (entry,) = result.unexplained
    assert (entry.matrix, entry.row, entry.column) == ("F", "dV_n", "dV_e")
    assert "missing term: the written entry lacks -omega_ie*cos(phi)" in entry.reason
    assert entry.magnitude == pytest.approx(7.2921151467e-5 * 0.8660254038, rel=1e-6)
    declared = cc.HandModelError("F", "dV_n", "dV_e", "the hand model leaves out a Coriolis term")
    fixed = cc.cross_check(pair(hand_model_errors=(declared,)), paper_derived, twin)
    assert [e.status for e in fixed.entries if e.row == "dV_n" and e.column == "dV_e"] == ["hand_model_error"]
    assert fixed.unexplained == []


def test_report_has_one_record_per_entry_with_the_issue_fields(paper_model, paper_derived, tmp_path):
    result = cc.cross_check(pair(conventions=(GYRO_SIGN,)), paper_derived, derive(twin_of(paper_model)))
    markdown, data = cc.write_crosscheck_report([result], tmp_path)
    record = json.loads(data.read_text())
    assert len(record["entries"]) == len(result.entries)
    assert all(list(e) == sorted(cc.RECORD_FIELDS) for e in record["entries"])
    assert record["pairs"][0]["unexplained"] == 0
    assert "Unexplained differences: **0**" in markdown.read_text()


def test_a_hand_parameter_the_twin_spells_otherwise_must_be_renamed(paper_model, paper_derived):
    renamed = tuple(dataclasses.replace(p, symbol="R_earth") if p.symbol == "R" else p for p in paper_model.parameters)
    equations = {s.name: sp.sstr(paper_model.dynamics[s.name]).replace("R", "R_earth") for s in paper_model.states}
    twin = ErrorModel.build(name="t", states=paper_model.states, noises=paper_model.noises, parameters=renamed,
                            dynamics=equations, measurements=paper_model.measurements)
    with pytest.raises(ModelError, match=r"hand parameter\(s\) R have no parameter of that name"):
        cc.cross_check(pair(), paper_derived, derive(twin))
    result = cc.cross_check(pair(symbols={"R": "R_earth"}), paper_derived, derive(twin))
    assert result.differences == []


def test_a_twin_with_other_states_is_refused_naming_both_lists(paper_derived):
    from modelgen.model.loading import load_model

    with pytest.raises(ModelError, match="missing in the twin: dV_dn, dV_de"):
        cc.cross_check(pair(), paper_derived, derive(load_model("ned_inertial16")))


def test_twin_states_the_hand_model_leaves_out_are_couplings_its_declared_approximation_drops(paper_model):
    from modelgen.model.loading import load_model

    hand = derive(load_model("ned_inertial16"))
    equations = {s.name: paper_model.dynamics[s.name] for s in paper_model.states}
    equations["velocity_error_north"] = sp.sstr(equations["velocity_error_north"]) + " + a_n*dV_dn"
    twin = dataclasses.replace(ErrorModel.build(
        name="t", states=paper_model.states, noises=paper_model.noises, parameters=paper_model.parameters, dynamics=equations,
    ), check=paper_model.check)
    with pytest.raises(ModelError, match="not declared unmodelled: dV_dn, dV_de"):
        cc.cross_check(cc.Pair("ned_inertial16", "t"), hand, derive(twin))
    doppler = cc.Unmodelled(("dV_dn", "dV_de"), (), "no Doppler states", "a pure-inertial model has no Doppler radar")
    result = cc.cross_check(cc.Pair("ned_inertial16", "t", unmodelled=(doppler,)), hand, derive(twin))
    (coupling,) = result.differences
    assert (coupling.row, coupling.column, coupling.status, coupling.hand) == ("dV_n", "dV_dn", "approximation", "0")
    assert coupling.magnitude == pytest.approx(0.006705375157442078) and "no Doppler states" in coupling.reason


def test_pairs_file_with_an_unknown_key_or_a_convention_on_no_state_is_refused(paper_derived, tmp_path):
    bad = tmp_path / "crosscheck.yaml"
    bad.write_text("pairs:\n  - {hand: a, twin: b, colour: red}\n")
    with pytest.raises(ModelError, match=r"crosscheck\.yaml:2: pairs\[0\]: unknown key .colour."):
        cc.load_pairs(bad)
    wrong = cc.Convention("sign", ("no_such_state",), (), "x")
    with pytest.raises(ModelError, match="no_such_state"):
        cc.signs(pair(conventions=(wrong,)), paper_derived.model)


# -- the built-in pairs (modelgen/data/crosscheck.yaml) -----------------------------------------------
PAIRS = cc.load_pairs()


@pytest.fixture(scope="module")
def builtin_results(derived_builtin):
    """Each pair's cross-check, every model loaded and derived once."""
    from modelgen.model.navigation_model.approximation_notes import neglected_terms

    out = {}
    for p in PAIRS:
        twin = derived_builtin(p.twin)
        out[p.hand] = cc.cross_check(p, derived_builtin(p.hand), twin, neglected_terms(twin))
    return out


@pytest.mark.parametrize("hand", [p.hand for p in PAIRS])
def test_every_hand_model_equals_its_twin_but_for_declared_approximations_and_conventions(builtin_results, hand):
    result = builtin_results[hand]
    assert [(e.matrix, e.row, e.column, e.reason) for e in result.unexplained] == []
    assert result.counts()["equal"] > 0
    assert all(e.magnitude is not None for e in result.entries if e.status == "approximation"), "every dropped term has a size"


def test_every_twin_file_is_in_a_pair_and_every_pair_has_its_twin():
    from modelgen.fileio.datafiles import package_path

    twins = {path.stem for path in package_path("models").glob("*_twin.yaml")}
    assert twins == {p.twin for p in PAIRS}


def test_the_paper_models_differ_from_their_twins_by_the_drift_sign_and_the_paper_assumptions_only(builtin_results):
    for hand in ("ned_doppler18", "ned_inertial16"):
        result = builtin_results[hand]
        conventions = [e for e in result.entries if e.status == "convention"]
        assert {e.row for e in conventions} == {"alpha", "beta", "gamma"} and len(conventions) == 18
        approximations = {e.reason for e in result.entries if e.status == "approximation"}
        named = {"no_vertical_channel", "no_height_in_radii", "single_earth_radius", "constant_gravity"}
        assert all(any(name in reason for name in named) for reason in approximations), approximations
        couplings = [e.magnitude for e in result.entries if (e.row, e.column) == ("dV_e", cc.REMOVED_STATE)]
        # 2 w_ie cos(30 deg) + V_e / R_N(30 deg): the Coriolis coupling of dV_d the paper drops with the vertical channel
        assert couplings and max(couplings) == pytest.approx(2 * 7.2921151467e-5 * 0.8660254 + 83.333333 / 6383594.8, rel=1e-5)


def test_crosscheck_report_of_the_builtin_pairs_has_no_unexplained_entry(builtin_results, tmp_path):
    markdown, data = cc.write_crosscheck_report(list(builtin_results.values()), tmp_path)
    record = json.loads(data.read_text())
    assert {p["model"] for p in record["pairs"]} == {p.hand for p in PAIRS}
    assert all(p["unexplained"] == 0 for p in record["pairs"])
    assert all(e["status"] in cc.STATUSES for e in record["entries"])


def test_a_pair_whose_twin_file_is_missing_fails_loudly():
    from modelgen.checks.twins import require_twin

    with pytest.raises(ModelError, match="modelgen/models/no_such_model_twin.yaml does not exist"):
        require_twin("no_such_model_twin")
