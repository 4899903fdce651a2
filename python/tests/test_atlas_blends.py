"""tools/atlas_blends.py: the rigid fit and the mixes it makes of the pelvis atlas's members (the
mixes' tests skip, saying so, where ../shared is absent)."""

import pathlib
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import atlas_blends  # noqa: E402

ATLAS = ROOT.parent / "shared" / "data" / "pelvis-atlas"


def turned(A, angle, shift, scale=1.0):
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(0.3), -np.sin(0.3)], [0.0, np.sin(0.3), np.cos(0.3)]]
    )
    return scale * A @ R.T + shift


def test_onto_undoes_a_rigid_motion():
    A = np.random.default_rng(7).normal(scale=30.0, size=(200, 3))
    B = turned(A, 0.8, np.array([12.0, -40.0, 5.0]))
    assert np.abs(atlas_blends.onto(A, B) - A).max() < 1e-9


def test_onto_does_not_undo_a_scaling_too():
    # Companion: a member 10 % larger is turned and moved, not shrunk, so it does not land on A.
    A = np.random.default_rng(7).normal(scale=30.0, size=(200, 3))
    B = turned(A, 0.8, np.array([12.0, -40.0, 5.0]), scale=1.1)
    assert np.abs(atlas_blends.onto(A, B) - A).max() > 1.0


def atlas_mixes():
    if not (ATLAS / "hemipelves").is_dir():
        pytest.skip(f"{ATLAS} is absent: the mixes are made from the shared pelvis atlas")
    return atlas_blends.mixes(str(ATLAS))


def member(name):
    return atlas_blends.extractor(str(ATLAS)).load_vtk(str(ATLAS / "hemipelves" / f"{name}.vtk"))


def members_of(mix_name):
    """The two members a mix was made of: i0204_lhip -> a02_lhip, a04_lhip."""
    pair, side = mix_name.split("_")
    return f"a{pair[1:3]}_{side}", f"a{pair[3:5]}_{side}"


def test_a_mix_between_two_members_lies_halfway_and_one_beyond_lies_outside():
    seen = set()
    for name, V, F in atlas_mixes():
        a, b = members_of(name)
        (VA, FA), (VB, _) = member(a), member(b)
        assert np.array_equal(F, FA)
        to_a = np.linalg.norm(V - VA, axis=1)
        to_b = np.linalg.norm(V - atlas_blends.onto(VA, VB), axis=1)
        moving = to_a + to_b > 1e-6
        ratio = np.median(to_a[moving] / to_b[moving])
        if name.startswith("i"):
            assert abs(ratio - 1.0) < 1e-6, (name, ratio)
        else:
            # Companion: A pushed away from B is 0.4 of their gap from A and 1.4 from B, which
            # the halfway check would refuse.
            assert abs(ratio - 0.4 / 1.4) < 1e-6, (name, ratio)
            assert abs(ratio - 1.0) > 0.5
        seen.add(name[0])
        if seen == {"i", "e"}:
            break
    assert seen == {"i", "e"}


def test_a_member_without_an_acetabulum_takes_no_part():
    names = [name for name, _, _ in atlas_mixes()]
    kept = {p.stem for p in (ATLAS / "acetabula").glob("*.stl")}
    used = {m for n in names for m in members_of(n)}
    assert used == kept
    # Companion: the atlas has a hemipelvis without an acetabulum (a25_lhip), which the mixes
    # would have used had they taken every hemipelvis.
    every = {p.stem for p in (ATLAS / "hemipelves").glob("*.vtk")}
    assert every - kept and not (every - kept) & used


def test_another_step_and_other_shares_make_other_mixes():
    if not (ATLAS / "hemipelves").is_dir():
        pytest.skip(f"{ATLAS} is absent: the mixes are made from the shared pelvis atlas")
    lhip = sorted(p.stem for p in (ATLAS / "acetabula").glob("*_lhip.stl"))
    seen = set()
    for name, V, _ in atlas_blends.mixes(str(ATLAS), step=2, mix=(0.25, -0.2)):
        a, b = members_of(name)
        if b.endswith("_lhip"):
            # Each member mixed with the one two on in its side's list.
            assert lhip.index(b) == (lhip.index(a) + 2) % len(lhip), name
        (VA, _), (VB, _) = member(a), member(b)
        to_a = np.linalg.norm(V - VA, axis=1)
        to_b = np.linalg.norm(V - atlas_blends.onto(VA, VB), axis=1)
        moving = to_a + to_b > 1e-6
        ratio = np.median(to_a[moving] / to_b[moving])
        want = 0.25 / 0.75 if name.startswith("i") else 0.2 / 1.2
        assert abs(ratio - want) < 1e-6, (name, ratio)
        # Companion: the default shares' ratios are refused by the same check.
        assert abs(ratio - (1.0 if name.startswith("i") else 0.4 / 1.4)) > 0.05
        seen.add(name[0])
        if seen == {"i", "e"}:
            break
    assert seen == {"i", "e"}


def test_shares_and_steps_that_make_no_mix_are_refused():
    for argv in (["out", "--mix", "0.5"], ["out", "--mix", "0,0.3"], ["out", "--mix", "a,b"],
                 ["out", "--mix", "1,-0.4"], ["out", "--step", "0"]):
        with pytest.raises(SystemExit) as e:
            atlas_blends.arguments(argv)
        assert e.value.code == 2, argv
    # Companion: the defaults and a valid choice are taken.
    assert atlas_blends.arguments(["out"])[2:] == (1, (0.5, -0.4))
    assert atlas_blends.arguments(["out", "--step", "3", "--mix", "0.3,-0.25"])[2:] == (3, (0.3, -0.25))
