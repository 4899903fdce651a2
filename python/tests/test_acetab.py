"""The Python package against the command line and against itself (run by .ci/run after the Rust
tests: python -m pytest python/tests)."""

import json
import math
import os
import pathlib
import subprocess

import numpy as np
import pytest

import acetab

ROOT = pathlib.Path(__file__).resolve().parents[2]
CASE = ROOT / "examples" / "case" / "case.json"
DICOM_CASE = ROOT / "examples" / "case-dicom" / "case.json"


def cli_reconstruct(case, out, *args):
    """`acetab reconstruct CASE --json`: the binary $ACETAB_CLI names (CI keeps the one the Rust
    tests built), else through cargo."""
    cli = os.environ.get("ACETAB_CLI")
    head = [cli] if cli else ["cargo", "run", "--release", "-q", "--bin", "acetab", "--"]
    cmd = [*head, "reconstruct", str(case), "--out", str(out), "--json", *args]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_reconstruct_case_gives_the_cli_cup(tmp_path):
    cli = cli_reconstruct(CASE, tmp_path / "cli")
    py = acetab.reconstruct_case(CASE, tmp_path / "py")
    assert abs(py["cup"]["diameter_mm"] - cli["cup"]["diameter_mm"]) < 1e-6
    assert py["cup"]["catalogue_mm"] == cli["cup"]["catalogue_mm"]
    assert py["cup"]["probabilities"] == cli["cup"]["probabilities"]
    # The same object as the command line's: every key of report.json, and the calibration
    # learned on the case's views (the paper's).
    assert set(py) == set(cli)
    assert py["calibration"] == cli["calibration"]
    assert py["calibration"]["name"] == "calibration/realistic.json"
    assert py["calibration"]["views_fit"] == "same"
    assert (tmp_path / "py" / "reconstruction.ply").is_file()
    assert json.loads((tmp_path / "py" / "report.json").read_text())["cup"] == py["cup"]


def test_another_method_is_not_the_cli_cup(tmp_path):
    # The companion: a wrong answer (ICP instead of SRVF) is told apart at the same tolerance.
    cli = cli_reconstruct(CASE, tmp_path / "cli")
    icp = acetab.reconstruct_case(CASE, method="icp", uncertainty_samples=2)
    assert icp["method"] == "icp"
    assert abs(icp["cup"]["diameter_mm"] - cli["cup"]["diameter_mm"]) > 1e-6


def test_the_dicom_case_gives_the_png_case_cup():
    png = acetab.reconstruct_case(CASE, uncertainty_samples=2)
    dcm = acetab.reconstruct_case(DICOM_CASE, uncertainty_samples=2)
    assert abs(png["cup"]["diameter_mm"] - dcm["cup"]["diameter_mm"]) < 0.05
    view = dcm["views"][0]
    assert view["k_source"] == ["dicom", "dicom", "image centre", "image centre"]
    assert view["dicom"]["spacing_tag"] == "ImagerPixelSpacing (0018,1164)"
    assert math.isclose(view["magnification_dicom"], 1100 / 900)


def case_arrays(path):
    case = json.loads(pathlib.Path(path).read_text())
    cameras = [
        {
            "k": [v["k"][n] for n in ("fx", "fy", "cx", "cy")],
            "r": np.array(v["r"]),
            "t": np.array(v["t"]),
            "width": v["width"],
            "height": v["height"],
            "name": v["name"],
        }
        for v in case["views"]
    ]
    contours = [
        [{"points": np.array(c["points"]), "closed": c["closed"]} for c in v["contours"]]
        for v in case["views"]
    ]
    return cameras, contours, case["template"]


def test_reconstruct_from_arrays_matches_the_case_file():
    cameras, contours, template = case_arrays(CASE)
    r = acetab.reconstruct(cameras, contours, template, uncertainty_samples=2)
    ref = acetab.reconstruct_case(CASE, uncertainty_samples=2)
    assert r["cup"]["diameter_mm"] == ref["cup"]["diameter_mm"]
    assert r["calibration"] == ref["calibration"]
    v, f = r["vertices"], r["faces"]
    assert v.dtype == np.float64 and v.ndim == 2 and v.shape[1] == 3
    assert f.dtype == np.int64 and f.shape[1] == 3 and f.max() < len(v) and f.min() >= 0
    # The vertices lie about the cup sphere.
    c, rad = np.array(r["sphere"]["center"]), r["sphere"]["radius"]
    assert abs(np.median(np.linalg.norm(v - c, axis=1)) - rad) < 2.0
    assert "vertices" not in ref
    # A (3, 3) K is the same camera.
    k = cameras[0]["k"]
    cameras[0]["k"] = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1]])
    r2 = acetab.reconstruct(cameras, contours, template, uncertainty_samples=2)
    assert r2["cup"]["diameter_mm"] == r["cup"]["diameter_mm"]


def test_clicks_reach_the_engine_as_in_a_case_file(tmp_path):
    """Ten clicks a view given as arrays with ``"clicked": True`` give the cup of the same case
    file with ``"clicked": true``; the companion: without the flag the cup differs."""
    cameras, contours, template = case_arrays(CASE)
    case = json.loads(CASE.read_text())
    for view, cs in zip(case["views"], contours):
        view.pop("image", None)
        pts = cs[0]["points"]
        keep = [round(i * (len(pts) - 1) / 9) if not cs[0]["closed"] else i * len(pts) // 10
                for i in range(10)]
        cs[0]["points"] = pts[keep]
        cs[0]["clicked"] = True
        view["contours"][0]["points"] = pts[keep].tolist()
        view["contours"][0]["clicked"] = True
    path = tmp_path / "clicks.json"
    path.write_text(json.dumps(case))
    ref = acetab.reconstruct_case(path, uncertainty_samples=2)
    r = acetab.reconstruct(cameras, contours, template, uncertainty_samples=2)
    assert r["cup"]["diameter_mm"] == ref["cup"]["diameter_mm"]
    for cs in contours:
        cs[0]["clicked"] = False
    plain = acetab.reconstruct(cameras, contours, template, uncertainty_samples=2)
    assert plain["cup"]["diameter_mm"] != r["cup"]["diameter_mm"]


def test_a_wrong_focal_length_moves_the_cup():
    cameras, contours, template = case_arrays(CASE)
    ref = acetab.reconstruct(cameras, contours, template, uncertainty_samples=2)
    for cam in cameras:
        cam["k"] = [1.1 * cam["k"][0], 1.1 * cam["k"][1], cam["k"][2], cam["k"][3]]
    moved = acetab.reconstruct(cameras, contours, template, uncertainty_samples=2)
    assert abs(moved["cup"]["diameter_mm"] - ref["cup"]["diameter_mm"]) > 0.05


def test_bad_arrays_are_refused_by_name():
    cameras, contours, template = case_arrays(CASE)
    cameras[1]["k"] = [-5500.0, 5500.0, 1024.0, 1024.0]
    with pytest.raises(acetab.AcetabError, match=r"views\[1\]\.k\.fx"):
        acetab.reconstruct(cameras, contours, template)
    cameras, contours, template = case_arrays(CASE)
    with pytest.raises(ValueError, match=r"cameras\[0\]\['r'\]"):
        cameras[0]["r"] = np.eye(2)
        acetab.reconstruct(cameras, contours, template)
    with pytest.raises(ValueError, match="3 cameras and 2 views"):
        acetab.reconstruct(*case_arrays(CASE)[:1], contours[:2], template)
    with pytest.raises(TypeError, match="metod"):
        acetab.reconstruct(*case_arrays(CASE), metod="icp")
    with pytest.raises(ValueError, match="method"):
        acetab.reconstruct(*case_arrays(CASE), method="cpd")


def test_bad_values_are_refused_by_name_before_the_engine():
    """Values the JSON between Python and the engine would lose or mangle (NaN, complex, a
    fraction of a pixel, a skewed K, a negative seed) are refused naming the argument."""
    def refused(pattern, mutate=None, **options):
        cameras, contours, template = case_arrays(CASE)
        if mutate:
            mutate(cameras, contours, template)
        with pytest.raises(ValueError, match=pattern):
            acetab.reconstruct(cameras, contours, template, **options)

    def nan_r(c, o, t):
        c[0]["r"] = np.full((3, 3), np.nan)

    def nan_point(c, o, t):
        o[1][0]["points"] = np.array(o[1][0]["points"], dtype=float)
        o[1][0]["points"][3, 0] = np.nan

    def complex_points(c, o, t):
        o[0][0]["points"] = np.array(o[0][0]["points"]) + 0j

    def skewed_k(c, o, t):
        k = c[0]["k"]
        c[0]["k"] = np.array([[k[0], 0.5, k[2]], [0, k[1], k[3]], [0, 0, 1]])

    def fractional_width(c, o, t):
        c[0]["width"] = 2048.7

    def negative_height(c, o, t):
        c[2]["height"] = -1

    def no_radius(c, o, t):
        del t["radius"]

    def infinite_radius(c, o, t):
        t["radius"] = math.inf

    refused(r"cameras\[0\]\['r'\]\[0, 0\] = nan: must be finite", nan_r)
    refused(r"contours\[1\]\[0\]\[3, 0\] = nan", nan_point)
    refused(r"contours\[0\]\[0\]: complex", complex_points)
    refused(r"cameras\[0\]\['k'\].*skew", skewed_k)
    refused(r"cameras\[0\]\['width'\] = 2048.7: expected a whole number", fractional_width)
    refused(r"cameras\[2\]\['height'\] = -1: image size", negative_height)
    refused(r"template: missing 'radius'", no_radius)
    refused(r"template\['radius'\] = inf: must be finite", infinite_radius)
    refused(r"seed=-5", seed=-5)
    refused(r"uncertainty_samples=-1", uncertainty_samples=-1)
    refused(r"pose_prior=\[1\.0, -2\.0\]: the SDs", refine_poses=True, pose_prior=(1, -2))
    refused(r"pose_prior\[1\] = nan: must be finite", refine_poses=True, pose_prior=(1, math.nan))
    refused(r"pose_prior: shape \(3,\)", refine_poses=True, pose_prior=(1, 2, 3))
    refused(r"pose_prior: needs refine_poses", pose_prior=(1, 2))
    # The companions: a whole-number float, a scaled K and numpy integers are taken as given.
    cameras, contours, template = case_arrays(CASE)
    ref = acetab.reconstruct(cameras, contours, template, uncertainty_samples=2)
    k = cameras[0]["k"]
    cameras[0]["k"] = 2.0 * np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1]])
    cameras[0]["width"] = float(cameras[0]["width"])
    cameras[1]["height"] = np.int32(cameras[1]["height"])
    same = acetab.reconstruct(
        cameras, contours, template, uncertainty_samples=np.int64(2), seed=np.uint8(1)
    )
    assert same["cup"]["diameter_mm"] == ref["cup"]["diameter_mm"]
    # A prior of the pose refinement's own reaches the engine, as numpy numbers too.
    refined = acetab.reconstruct(
        cameras, contours, template, uncertainty_samples=2, refine_poses=True,
        pose_prior=np.array([1.5, 3]),
    )
    assert refined["pose_prior"] == [1.5, 3.0]
    assert ref["pose_prior"] is None
    with pytest.raises(acetab.AcetabError, match=r"^gt=no_such_mesh\.stl"):
        acetab.simulate("no_such_mesh.stl", levels=[1], runs=1)


def test_the_shipped_prior_reaches_the_engine_as_on_the_command_line(tmp_path):
    cli = cli_reconstruct(CASE, tmp_path / "cli", "--prior", "default", "--uncertainty-samples", "2")
    py = acetab.reconstruct_case(CASE, prior="default", uncertainty_samples=2)
    assert abs(py["cup"]["diameter_mm"] - cli["cup"]["diameter_mm"]) < 1e-6
    # The companion: without the prior the cup is another one.
    bare = acetab.reconstruct_case(CASE, uncertainty_samples=2)
    assert abs(bare["cup"]["diameter_mm"] - cli["cup"]["diameter_mm"]) > 1e-6
    with pytest.raises(acetab.AcetabError, match=r"prior=.*no_such_prior\.json"):
        acetab.reconstruct_case(CASE, prior=tmp_path / "no_such_prior.json")


def test_the_prior_region_cup_takes_its_calibrations_bias_off():
    # The shipped ideal prior-region calibration's bias, taken off the same runs' raw cups
    # (calibration "none"); the companion: the raw cups are not the calibrated ones.
    kw = dict(levels=[1], runs=1, prior="default", cup_estimator="prior-region")
    raw = acetab.simulate("phantom", calibration="none", **kw)
    shipped = acetab.simulate("phantom", **kw)
    bias = json.loads((ROOT / "calibration" / "ideal-prior-region.json").read_text())["bias_mm"]
    # (runs.csv keeps six decimals)
    assert abs(raw[0]["cup_diameter_mm"] - bias - shipped[0]["cup_diameter_mm"]) < 2e-6
    assert abs(raw[0]["cup_diameter_mm"] - shipped[0]["cup_diameter_mm"]) > 0.5
    with pytest.raises(ValueError, match="prior-region.*prior"):
        acetab.simulate("phantom", levels=[1], runs=1, cup_estimator="prior-region")
    with pytest.raises(ValueError, match="cup_estimator"):
        acetab.reconstruct_case(CASE, cup_estimator="sphere")
    # A calibration learned for the observed part is refused for it.
    with pytest.raises(acetab.AcetabError, match="estimator = observed-part"):
        acetab.reconstruct_case(
            CASE,
            prior="default",
            cup_estimator="prior-region",
            calibration=ROOT / "calibration" / "realistic.json",
        )


def test_reconstruct_case_errors_carry_the_engine_message(tmp_path):
    bad = json.loads(CASE.read_text())
    for v in bad["views"]:
        v.pop("image")
    bad["views"][0]["t"][2] = -5000.0
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(bad))
    with pytest.raises(acetab.AcetabError, match=r"bad\.json.*views\[0\]\.t.*not in front"):
        acetab.reconstruct_case(p, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(acetab.AcetabError, match="no_such.json"):
        acetab.reconstruct_case(tmp_path / "no_such.json")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    with pytest.raises(acetab.AcetabError, match="not empty"):
        acetab.reconstruct_case(CASE, tmp_path / "full")


def ellipse(n, shift=0, scale=1.0, angle=0.0):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    # No symmetry under a half turn (the cos 2t term), so the rotation is unambiguous.
    pts = np.c_[30 * np.cos(t) + 5 * np.cos(2 * t), 18 * np.sin(t) + 4 * np.sin(3 * t)]
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return np.roll(scale * pts @ rot.T, shift, axis=0)


def test_align_finds_a_moved_copy_and_tells_another_shape():
    a = ellipse(80)
    b = ellipse(120, shift=17, scale=2.0, angle=0.3)
    al = acetab.align(a, b, mode="closed", samples=150)
    assert al["gamma"].shape == (150,) and al["aligned"].shape == (150, 2)
    assert np.all(np.diff(al["gamma"]) >= -1e-12)
    assert al["distance"] < 0.05
    assert abs(abs(al["rotation_deg"]) - math.degrees(0.3)) < 3.0
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    square = np.concatenate([np.linspace(square[i], square[(i + 1) % 4], 20, endpoint=False)
                             for i in range(4)])
    other = acetab.align(a, square, mode="closed", samples=150)
    assert other["distance"] > 5 * al["distance"] and other["distance"] > 0.05
    part = acetab.align(ellipse(80)[10:50], b, mode="partial", samples=100)
    assert part["distance"] < 0.1
    with pytest.raises(ValueError, match="mode"):
        acetab.align(a, b, mode="both")
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        acetab.align(a[:, :1], b)
    with pytest.raises(ValueError, match="samples"):
        acetab.align(a, b, samples=3)
    # A negative or fractional count is a ValueError too, not Python's OverflowError.
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="samples"):
            acetab.align(a, b, samples=bad)


def test_simulate_is_seeded_and_reports_runs():
    runs = acetab.simulate("phantom", levels=[1], runs=2, methods=["srvf"], seed=7, threads=1)
    assert len(runs) == 2 and all(r["error"] == "" for r in runs)
    assert all(r["method"] == "srvf" and r["level"] == 1 for r in runs)
    assert all(0 < r["mae_mm"] < 3 for r in runs)
    again = acetab.simulate("phantom", levels=[1], runs=2, methods="srvf", seed=7, threads=2)
    assert [r["mae_mm"] for r in again] == [r["mae_mm"] for r in runs]
    other = acetab.simulate("phantom", levels=[1], runs=2, methods=["srvf"], seed=8, threads=1)
    assert [r["mae_mm"] for r in other] != [r["mae_mm"] for r in runs]
    with pytest.raises(acetab.AcetabError, match="no_such_mesh.stl"):
        acetab.simulate("no_such_mesh.stl", levels=[1], runs=1)
    with pytest.raises(ValueError, match="protocol"):
        acetab.simulate("phantom", protocol="clinical")
    # A study of nothing, or of a level or method twice, is refused (not an empty or doubled
    # list of runs); level 0, no start noise, runs (the companion).
    for kw, says in [
        (dict(levels=[]), r"levels=\[\]"),
        (dict(methods=[]), r"methods=\[\]"),
        (dict(levels=[1, 3, 1]), r"levels\[2\] = 1: listed twice"),
        (dict(methods=["icp", "srvf", "icp"]), r"methods\[2\] = icp: listed twice"),
    ]:
        with pytest.raises(ValueError, match=says):
            acetab.simulate("phantom", **{"levels": [1], "runs": 1, **kw})
    assert [r["level"] for r in acetab.simulate("phantom", levels=[0], runs=1)] == [0]
