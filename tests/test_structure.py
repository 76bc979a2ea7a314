"""Structural analysis: the seed's table, textbook mechanisms, the coaxial drive, format errors.

Every count here is an integer, so the assertions are exact. The rank decision itself uses the
relative singular-value cut-off 1e-8 (docs/structure.md); the shipped configurations keep the
smallest kept singular value above 0.04 and the largest dropped one below 1e-15 (checked below),
so the counts do not depend on the cut-off.
"""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from crankfmu.cli import main
from crankfmu.studies.structure import (MechanismError, analyse, load_mechanism, loads_mechanism,
                                        mechanism_from_dict, structure_report)

MECH = Path(__file__).resolve().parents[1] / "scenarios" / "mechanisms"


def result(name):
    return analyse(load_mechanism(MECH / f"{name}.toml"))


def formula_q(mech, W):
    """Malyshev's q from the description's joint counts, computed here independently."""
    n = len(mech.links)
    return W - 6 * n + sum((6 - j.f) for j in mech.joints)


def has(directions, *fragments):
    return all(any(fr in d for d in directions) for fr in fragments)


# -- the seed's table --------------------------------------------------------------------------
def test_seed_all_revolute_q3_by_both_formulas_and_the_rank():
    r = result("stand_drive_p1")
    assert (r["n"], r["p"], r["p_by_freedom"]) == (4, 5, {"1": 5})
    assert r["W_chebyshev"] == 2 and r["mobility"] == 2 and r["dof_total"] == 2
    assert r["q_malyshev"] == 3 and r["q_ozol"] == 3 and r["k"] == 1 and r["f"] == 5
    red = r["redundant"]
    assert red["count"] == 3
    # the seed: preloads about the axes y and z and along x (x = the pin axes)
    assert red["directions"][:2] == ["rotation about y", "rotation about z"]
    assert red["directions"][2].startswith("translation along x")
    assert r["local_mobilities"]["count"] == 0


@pytest.mark.parametrize("name, p_by", [
    ("stand_drive_p2p3", {"1": 1, "2": 2, "3": 2}),
    ("stand_drive_p2p3_coaxial", {"1": 1, "2": 2, "3": 2}),
    ("stand_drive_p4", {"1": 3, "4": 2}),
    ("stand_drive_p4_coaxial", {"1": 3, "4": 2}),
])
def test_seed_self_aligning_variants_q0_with_three_local_mobilities(name, p_by):
    r = result(name)
    assert r["p_by_freedom"] == p_by and r["f"] == 5 + 6          # the seed: sum raised by 6
    assert r["redundant"] == {"count": 0, "directions": []}
    assert r["dof_total"] == 5 and r["mobility"] == 2
    assert r["local_mobilities"]["count"] == 3 and len(r["local_mobilities"]["directions"]) == 3
    assert r["W_chebyshev"] is None                                 # not planar any more
    assert r["q_malyshev"] == -3 and r["q_ozol"] == -3             # formulas with W = 2
    assert r["q_formulas_total"] == 0                               # formulas with W = 5
    text = structure_report(MECH / f"{name}.toml")
    assert "with W = 2 give q = -3 (Malyshev) = -3 (Ozol)" in text
    assert "q = 0 holds with W = 5 (2 main + 3 local)" in text


def test_local_mobilities_of_the_coaxial_self_aligning_drives_are_named():
    locs = result("stand_drive_p2p3_coaxial")["local_mobilities"]["directions"]
    assert has(locs, "stand rotates about the line C–F", "stand translates along x")
    locs = result("stand_drive_p4_coaxial")["local_mobilities"]["directions"]
    assert has(locs, "stand rotates about the line C–F", "stand translates along x")


def test_coaxial_all_revolute_drive_has_one_redundant_constraint_more():
    r = result("stand_drive_p1_coaxial")
    assert r["q_malyshev"] == 3 and r["q_ozol"] == 3            # the formulas with W = 2
    assert r["redundant"]["count"] == 4                          # the rank: one more
    assert r["dof_total"] == 3 and r["mobility"] == 2
    assert r["local_mobilities"]["directions"] == ["stand rotates about the line C–F"]
    assert has(r["redundant"]["directions"], "rotation about y", "rotation about z",
               "the lengths of rod2 (A–C) and rod4 (F–H) must agree")
    assert r["planar"]["q"] == 1          # in the plane too: the rod-length equality


@pytest.mark.parametrize("name, q", [("stand_drive_p1_guided", 7), ("stand_drive_p2p3_guided", 1),
                                     ("stand_drive_p4_guided", 1)])
def test_guides_that_hold_the_stand_keep_the_rod_length_constraint(name, q):
    r = result(name)
    assert r["redundant"]["count"] == q and r["dof_total"] == 1 and r["mobility"] == 1
    assert has(r["redundant"]["directions"], "coupled over loops", "rod2 (A–C)", "rod4 (F–H)")


# -- textbook mechanisms: the rank count agrees with the formulas at the known W ---------------
@pytest.mark.parametrize("name, W, q, local, cheb", [
    ("bennett_rrrr", 1, 3, 0, None),          # spatial RRRR (Bennett): q = 3
    ("rssr", 1, 0, 1, None),                  # RSSR: q = 0 with one local mobility
    ("hammer_crank_rocker", 1, 3, 0, 1),      # planar four-bar
    ("slider_crank", 1, 3, 0, 1),
    ("stephenson_press", 1, 6, 0, 1),         # Stephenson six-bar: two loops
    ("planetary_gear", 2, 2, 0, 2),           # gear meshes: p4 in space, p2 in the plane
])
def test_rank_count_agrees_with_formulas_on_known_mechanisms(name, W, q, local, cheb):
    mech = load_mechanism(MECH / f"{name}.toml")
    r = analyse(mech)
    assert r.mobility == W and r.local_mobilities["count"] == local
    assert r.redundant["count"] == q == formula_q(mech, W + local)
    assert r.q_malyshev == formula_q(mech, W) and r.q_ozol == r.q_malyshev
    assert r.W_chebyshev == cheb
    if cheb is not None:
        assert r.planar["q"] == 0 and r.planar["dof"] == W   # planar: no redundant constraint


def test_rssr_local_mobility_is_the_rod_spin():
    r = result("rssr")
    assert r.local_mobilities["directions"] == ["rod rotates about the line B–C"]
    assert r.q_malyshev == -1        # W = 1 in the formula forgets the spin


def test_stephenson_redundant_constraints_belong_to_each_loop():
    d = result("stephenson_press").redundant["directions"]
    assert sum(x.startswith("loop 1") for x in d) == 3
    assert sum(x.startswith("loop 2") for x in d) == 3
    assert has(d, "rotation about x", "rotation about y", "translation along z")


def test_generic_spatial_rrrr_is_a_structure():
    """Bennett's proportions broken: the same counts, but the rank sees a rigid loop."""
    text = (MECH / "bennett_rrrr.toml").read_text().replace(
        "axis = [0.0, 0.6666666666666666, 0.7453559924999299]", "axis = [0.0, 0.6, 0.8]")
    r = analyse(loads_mechanism(text, "bennett_perturbed"))
    assert r.dof_total == 0 and r.redundant["count"] == 2


def test_result_does_not_depend_on_the_coordinate_frame():
    """Shift the whole drive by 10 m and turn it: the counts survive the conditioning."""
    data = tomllib.loads((MECH / "stand_drive_p1_coaxial.toml").read_text())
    base = analyse(mechanism_from_dict(data, "base"))
    c, s = math.cos(0.7), math.sin(0.7)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    for j in data["joints"]:
        j["point"] = list(rot @ np.array(j["point"], dtype=float) + 10.0)
        j["axis"] = list(rot @ np.array(j["axis"], dtype=float))
    r = analyse(mechanism_from_dict(data, "moved"))
    for key in ("dof_total", "mobility", "rank", "q_malyshev"):
        assert r[key] == base[key]
    assert r["redundant"]["count"] == base["redundant"]["count"] == 4
    assert r["local_mobilities"]["directions"] == ["stand rotates about the line C–F"]


def test_rank_decisions_of_all_shipped_files_are_clear_cut():
    files = sorted(MECH.glob("*.toml"))
    assert len(files) == 15
    for path in files:
        r = analyse(load_mechanism(path))
        s = np.array(r.singular_values)
        assert s[r.rank - 1] > 0.04, path.name
        assert r.rank == s.size or s[r.rank] < 1e-15, path.name
        assert not r.notes or "singular" not in " ".join(r.notes)


# -- report and JSON ---------------------------------------------------------------------------
def test_json_report_has_the_required_keys():
    d = json.loads(structure_report(MECH / "stand_drive_p1.toml", as_json=True))
    for key in ("n", "p", "W_chebyshev", "q_malyshev", "q_ozol", "dof_total", "mobility",
                "local_mobilities", "redundant"):
        assert key in d
    assert d["redundant"]["count"] == 3 and len(d["redundant"]["directions"]) == 3


def test_cli_main_prints_and_returns_codes(capsys, tmp_path):
    assert main(["structure", str(MECH / "rssr.toml")]) == 0
    assert "local: rod rotates about the line B–C" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text("[mechanism]\nname = 3\n")
    assert main(["structure", str(bad)]) == 2  # a MechanismError: mapped by cli.main alone
    assert capsys.readouterr().err.startswith("error: ")


# -- errors ------------------------------------------------------------------------------------
GOOD = """
[mechanism]
name = "four_bar"
links = ["crank", "coupler", "rocker"]

[[joints]]
name = "O"
between = ["frame", "crank"]
type = "R"
point = [0, 0, 0]
axis = [0, 0, 1]

[[joints]]
name = "A"
between = ["crank", "coupler"]
type = "R"
point = [0.1, 0, 0]
axis = [0, 0, 1]

[[joints]]
name = "B"
between = ["coupler", "rocker"]
type = "R"
point = [0.4, 0.3, 0]
axis = [0, 0, 1]

[[joints]]
name = "Q"
between = ["rocker", "frame"]
type = "R"
point = [0.5, 0, 0]
axis = [0, 0, 1]
"""


def error_for(text, tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text(text)
    with pytest.raises(MechanismError) as info:
        load_mechanism(path)
    msg = str(info.value)
    assert str(path) in msg
    return msg


def test_good_description_loads(tmp_path):
    path = tmp_path / "four_bar.toml"
    path.write_text(GOOD)
    assert analyse(load_mechanism(path)).redundant["count"] == 3


def test_disconnected_mechanism_is_an_error(tmp_path):
    # the rocker loses its frame joint and the coupler-rocker joint: rocker hangs in the air
    text = GOOD.replace('between = ["coupler", "rocker"]', 'between = ["coupler", "crank"]') \
               .replace('between = ["rocker", "frame"]', 'between = ["crank", "frame"]')
    msg = error_for(text, tmp_path)
    assert "rocker" in msg and "not a connected mechanism" in msg
    # coupler and rocker joined to each other only: an island apart from the frame
    text = GOOD.replace('between = ["crank", "coupler"]', 'between = ["crank", "frame"]') \
               .replace('between = ["rocker", "frame"]', 'between = ["rocker", "coupler"]')
    msg = error_for(text, tmp_path)
    assert "['coupler', 'rocker'] are not connected to the frame" in msg


def test_floating_subchain_is_an_error(tmp_path):
    text = GOOD.replace('between = ["frame", "crank"]', 'between = ["coupler", "crank"]') \
               .replace('between = ["rocker", "frame"]', 'between = ["rocker", "crank"]')
    msg = error_for(text, tmp_path)
    assert "no joint touches the frame" in msg


def test_unknown_key_is_named_with_the_allowed_ones(tmp_path):
    msg = error_for(GOOD.replace('axis = [0, 0, 1]\n\n[[joints]]\nname = "A"',
                                 'axs = [0, 0, 1]\n\n[[joints]]\nname = "A"'), tmp_path)
    assert "joints[0].axs: unknown key" in msg and "allowed: name, between, type, free" in msg


def test_bad_joint_type_and_free_axis(tmp_path):
    msg = error_for(GOOD.replace('type = "R"', 'type = "Q"', 1), tmp_path)
    assert "joints[0] (O).type" in msg and "R, P, C, U, S, E" in msg
    msg = error_for(GOOD.replace('type = "R"', 'free = ["rz", "sx"]', 1), tmp_path)
    assert "joints[0] (O).free[1]" in msg and '"rx"' in msg


def test_u_joint_needs_a_second_axis_and_links_must_exist(tmp_path):
    msg = error_for(GOOD.replace('type = "R"', 'type = "U"', 1), tmp_path)
    assert "axis2" in msg and "U joint" in msg
    msg = error_for(GOOD.replace('"rocker", "frame"', '"rockr", "frame"'), tmp_path)
    assert "joints[3] (Q).between" in msg and "'rockr' is not declared" in msg


def test_not_toml_and_missing_table(tmp_path):
    assert "not valid TOML" in error_for("[mechanism\nname = 1", tmp_path)
    assert "mechanism: table is missing" in error_for("[[joints]]\nname = 'a'", tmp_path)
