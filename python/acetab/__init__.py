"""acetab: reconstruct the acetabulum from three pelvic X-rays and predict the cup size.

Python bindings of the acetab engine (Rust). Four functions:

- ``reconstruct_case(path, out=None, **options)``: a case file (JSON, as ``acetab reconstruct``
  reads it), the same report object as ``acetab reconstruct --json``.
- ``reconstruct(cameras, contours, template, **options)``: the same from numpy arrays; the
  reconstructed surface as numpy arrays and the cup.
- ``align(a, b, mode="closed", samples=200)``: SRVF elastic alignment of two curves.
- ``simulate(gt, levels, runs, methods, ...)``: a simulation study's runs.

Errors the engine raises are ``AcetabError`` with the engine's message (the file, the field and
the value); arguments of the wrong kind raise ``TypeError`` or ``ValueError``.

Not a medical device: research software, see the project's README.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

from . import _acetab
from ._acetab import AcetabError

__all__ = [
    "AcetabError",
    "align",
    "reconstruct",
    "reconstruct_case",
    "simulate",
    "__version__",
]

__version__: str = _acetab.version()

PathLike = Union[str, "os.PathLike[str]"]

_RECON_OPTIONS = (
    "method",
    "catalogue",
    "refine_poses",
    "pose_prior",
    "uncertainty_samples",
    "calibration",
    "seed",
    "contours",
    "prior",
    "cup_estimator",
)


def _options(options: Mapping[str, Any], allowed: Sequence[str], where: str) -> str:
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise TypeError(
            f"{where}() got unexpected keyword argument(s) {', '.join(unknown)}; "
            f"it takes {', '.join(allowed)}"
        )
    out = {}
    for k, v in options.items():
        if k in ("calibration", "prior") and v is not None:
            v = os.fspath(v)
        if isinstance(v, np.generic):
            v = v.item()  # numpy scalars as plain numbers
        if k == "seed":
            v = _whole(v, k)
            if not 0 <= v < 2**64:
                raise ValueError(f"seed={v}: must be from 0 to 2**64 - 1")
        if k == "uncertainty_samples":
            v = _whole(v, k)
            if not 0 <= v <= 1000:
                raise ValueError(f"uncertainty_samples={v}: must be 2 to 1000")
        if k == "pose_prior" and v is not None:
            v = _pose_prior(v)
        out[k] = v
    return json.dumps(out)


def _pose_prior(v: Any) -> List[float]:
    """``pose_prior``: the pose refinement's prior SDs (degrees, mm), two numbers above 0."""
    a = _float_list(v, (2,), "pose_prior")
    if not all(x > 0 for x in a):
        raise ValueError(f"pose_prior={a}: the SDs (degrees, mm) must be above 0")
    return a


def reconstruct_case(
    path: PathLike,
    out: Optional[PathLike] = None,
    *,
    force: bool = False,
    **options: Any,
) -> Dict[str, Any]:
    """Reconstruct the case file at ``path`` as ``acetab reconstruct`` does.

    Writes reconstruction.ply, cup.json, report.json and the pictures into ``out`` (which must be
    new or empty unless ``force``); with ``out=None`` they go to a temporary folder that is
    removed. Returns report.json's object: ``cup`` (``diameter_mm``, ``catalogue_mm``,
    ``sd_mm``, ``probabilities``, ...), ``sphere``, ``views`` (intrinsics and where they came
    from, DICOM magnification), ``log``, ``calibration`` (which one, and whether it was learned
    on the case's views), ``warnings``, ``provenance``, ``pose_prior`` (the pose refinement's
    prior SDs, None when the poses were taken as given).

    Options (the command line's flags, same defaults): ``method`` ("srvf", "icp",
    "icp-normvec"), ``catalogue`` ("40:70:2" or "44,46,48"), ``refine_poses`` (bool),
    ``pose_prior`` (with ``refine_poses``: the refinement's prior SDs, (degrees, mm), default
    (2, 5)),
    ``uncertainty_samples`` (2-1000, default 16), ``calibration`` (None: the shipped realistic
    one learned on the case's views, the AP and Judet views' or the paper's; "none"; or a file
    from ``acetab calibrate``), ``seed`` (default 1), ``contours``
    ("alpha-shape" or "silhouette"), ``prior`` (the population shape prior: "none", the
    default; "default", the shipped one; or a file from ``acetab prior build``),
    ``cup_estimator`` ("observed-part", the default, or with a prior "prior-region"; the
    calibration must have been learned for it, and its bias is taken off the cup).

    Raises AcetabError when the case is refused or the reconstruction fails.
    """
    opts = _options(options, _RECON_OPTIONS, "reconstruct_case")
    text = _acetab.reconstruct_case_json(
        os.fspath(path), None if out is None else os.fspath(out), bool(force), opts
    )
    return json.loads(text)


def _float_list(x: Any, shape: Sequence[Optional[int]], name: str) -> Any:
    try:
        raw = np.asarray(x)
    except ValueError as e:  # ragged nested lists
        raise ValueError(f"{name}: not an array ({e})") from None
    if np.iscomplexobj(raw):
        raise ValueError(f"{name}: complex numbers; expected real ones")
    try:
        a = raw.astype(np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: not numbers ({e})") from None
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: shape {a.shape}, expected {want}")
    if not np.all(np.isfinite(a)):
        at = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        where = name + (str(list(at)) if at else "")
        raise ValueError(f"{where} = {a[at]}: must be finite")
    return a.tolist()


def _intrinsics(k: Any, name: str) -> Dict[str, float]:
    a = np.asarray(_float_list(k, (None,) * np.ndim(k), name))
    if a.shape == (3, 3):
        if a[2, 2] == 0:
            raise ValueError(f"{name}[2, 2] = 0: not an intrinsic matrix")
        a = a / a[2, 2]
        off = (a[0, 1], a[1, 0], a[2, 0], a[2, 1])
        if any(abs(v) > 1e-9 * abs(a[0, 0]) for v in off):
            raise ValueError(
                f"{name}: {a.tolist()} has skew or a non-zero bottom row; expected "
                "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
            )
        return {"fx": a[0, 0], "fy": a[1, 1], "cx": a[0, 2], "cy": a[1, 2]}
    if a.shape == (4,):
        return dict(zip(("fx", "fy", "cx", "cy"), a.tolist()))
    raise ValueError(f"{name}: shape {a.shape}, expected (4,) fx, fy, cx, cy or a (3, 3) K")


def _whole(x: Any, name: str) -> int:
    """A whole number given as an int (or a float with no fraction), else ValueError."""
    if isinstance(x, (bool, np.bool_)):
        raise ValueError(f"{name} = {x!r}: expected a whole number")
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)) and math.isfinite(x) and float(x).is_integer():
        return int(x)
    raise ValueError(f"{name} = {x!r}: expected a whole number")


def _pixels(x: Any, name: str) -> int:
    """An image size: a whole number the engine can take (it says 1..65536 pixels)."""
    v = _whole(x, name)
    if not 0 <= v < 2**32:
        raise ValueError(f"{name} = {v}: image size must be 1..65536 pixels")
    return v


def _field(m: Mapping[str, Any], key: str, name: str) -> Any:
    try:
        return m[key]
    except KeyError:
        raise ValueError(f"{name}: missing {key!r}") from None


def _contours(view: Any, name: str) -> List[Dict[str, Any]]:
    if isinstance(view, Mapping) or (isinstance(view, np.ndarray) and view.ndim == 2):
        view = [view]
    out = []
    for i, c in enumerate(view):
        where = f"{name}[{i}]"
        if isinstance(c, Mapping):
            closed = bool(c.get("closed", True))
            pts = c["points"]
        else:
            closed, pts = True, c
        entry = {"points": _float_list(pts, (None, 2), where), "closed": closed}
        if isinstance(c, Mapping) and "clicked" in c:
            entry["clicked"] = bool(c["clicked"])
        out.append(entry)
    return out


def reconstruct(
    cameras: Sequence[Mapping[str, Any]],
    contours: Sequence[Any],
    template: Mapping[str, Any],
    **options: Any,
) -> Dict[str, Any]:
    """Reconstruct the acetabulum from views and their annotated rims given as arrays.

    ``cameras``: one mapping per view with ``k`` ((4,) fx, fy, cx, cy in pixels, or a (3, 3)
    K), ``r`` ((3, 3) world-to-camera rotation), ``t`` ((3,) mm), ``width`` and ``height``
    (pixels), optionally ``name``. ``contours``: per view, an (N, 2) array of pixel points (a
    closed rim), a mapping ``{"points": (N, 2), "closed": bool}`` (with ``"clicked": True``
    where the points are clicks on the rim, as in a case file), or a list of those.
    ``template``: ``{"center": (3,), "radius": mm, "axis": (3,)}``, the start placement.
    Options as for ``reconstruct_case``.

    Returns ``vertices`` ((V, 3) float64, mm), ``faces`` ((F, 3) int64), ``cup`` (as in
    ``reconstruct_case``), ``sphere`` (``center``, ``radius``), ``log``, ``views``,
    ``calibration``, ``warnings``, ``method``, ``pose_prior`` (the refinement's prior SDs, None
    without it). Writes nothing. Raises AcetabError when the input is refused (naming the
    field) or the reconstruction fails.
    """
    if len(cameras) != len(contours):
        raise ValueError(
            f"{len(cameras)} cameras and {len(contours)} views of contours: one each"
        )
    views = []
    for i, (cam, cs) in enumerate(zip(cameras, contours)):
        at = f"cameras[{i}]"
        v: Dict[str, Any] = {
            "k": _intrinsics(_field(cam, "k", at), f"{at}['k']"),
            "r": _float_list(_field(cam, "r", at), (3, 3), f"{at}['r']"),
            "t": _float_list(_field(cam, "t", at), (3,), f"{at}['t']"),
            "width": _pixels(_field(cam, "width", at), f"{at}['width']"),
            "height": _pixels(_field(cam, "height", at), f"{at}['height']"),
            "contours": _contours(cs, f"contours[{i}]"),
        }
        if "name" in cam:
            v["name"] = str(cam["name"])
        views.append(v)
    case = {
        "views": views,
        "template": {
            key: _float_list(_field(template, key, "template"), shape, f"template[{key!r}]")
            for key, shape in (("center", (3,)), ("radius", ()), ("axis", (3,)))
        },
    }
    opts = _options(options, _RECON_OPTIONS, "reconstruct")
    vertices, faces, report = _acetab.reconstruct_json(json.dumps(case), opts)
    result = json.loads(report)
    result["vertices"] = vertices
    result["faces"] = faces
    return result


def align(
    a: Any,
    b: Any,
    mode: str = "closed",
    samples: int = 200,
    anchor: float = 0.0,
) -> Dict[str, Any]:
    """SRVF elastic alignment of curve ``b`` to curve ``a`` ((N, 2) arrays of x, y).

    ``mode``: "closed" (both closed: rotation, seed and warp), "open" (ends correspond) or
    "partial" (``a`` an open arc matched to the best sub-arc of the closed ``b``). ``samples``:
    arc-length samples per curve. ``anchor``: weight of the position term (0: shape alone).

    Returns ``distance`` (0 = same shape), ``rotation_deg``, ``seed``, ``reversed``,
    ``gamma`` (the warp at a's samples, numpy), ``aligned`` (b's matched points, (samples, 2)),
    ``a_points`` (a's samples) and ``b_index`` (fractional vertex index in b).
    """
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    for name, c in (("a", a), ("b", b)):
        if c.ndim != 2 or c.shape[1] != 2:
            raise ValueError(f"{name}: shape {c.shape}; a curve is an (N, 2) array of x, y")
    samples = _whole(samples, "samples")
    if not 0 <= samples < 2**32:
        # (the engine names its own range for any count that fits)
        raise ValueError(f"samples = {samples}: expected a count of samples per curve")
    return _acetab.align(a, b, str(mode), samples, float(anchor))


def simulate(
    gt: PathLike,
    levels: Sequence[int] = (1, 3, 5),
    runs: int = 3,
    methods: Sequence[str] = ("srvf",),
    *,
    seed: int = 1,
    protocol: str = "ideal",
    refine_poses: bool = False,
    pose_prior: Optional[Sequence[float]] = None,
    threads: Optional[int] = None,
    uncertainty_samples: int = 0,
    calibration: Optional[PathLike] = None,
    prior: PathLike = "none",
    cup_estimator: str = "observed-part",
) -> List[Dict[str, Any]]:
    """Run a simulation study on the ground truth ``gt`` ("phantom" or a mesh file, mm).

    Each of ``runs`` runs per noise level (0-5) and method ("srvf", "icp", "icp-normvec" and the
    paper's variants) simulates the X-rays, reconstructs and measures. ``protocol``: "ideal" or
    "realistic" (pose and magnification errors, partial outlines, annotation drift);
    ``refine_poses`` and ``pose_prior`` as in ``reconstruct_case``.
    ``uncertainty_samples`` > 1 adds each run's cup uncertainty (``calibration`` as in
    ``reconstruct_case``; None: the protocol's shipped one); ``prior`` and ``cup_estimator`` as
    in ``reconstruct_case``. Seeded: the same arguments give the
    same runs, whatever ``threads``.

    Returns the runs (runs.csv's rows) as dicts: ``level``, ``run``, ``method``, ``seed``,
    ``mae_mm``, ``cup_diameter_mm``, ``gt_cup_diameter_mm``, ``error`` (empty unless the run
    failed), ...; a metric the run could not give is None.
    """
    opts = {
        "gt": os.fspath(gt),
        "levels": [int(x) for x in levels],
        "runs": int(runs),
        "methods": [str(m) for m in ([methods] if isinstance(methods, str) else methods)],
        "seed": int(seed),
        "protocol": str(protocol),
        "refine_poses": bool(refine_poses),
        "pose_prior": None if pose_prior is None else _pose_prior(pose_prior),
        "threads": None if threads is None else int(threads),
        "uncertainty_samples": int(uncertainty_samples),
        "calibration": None if calibration is None else os.fspath(calibration),
        "prior": os.fspath(prior),
        "cup_estimator": str(cup_estimator),
    }
    return json.loads(_acetab.simulate_json(json.dumps(opts)))
