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
        out[k] = v
    return json.dumps(out)


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
    from, DICOM magnification), ``log``, ``warnings``, ``provenance``.

    Options (the command line's flags, same defaults): ``method`` ("srvf", "icp",
    "icp-normvec"), ``catalogue`` ("40:70:2" or "44,46,48"), ``refine_poses`` (bool),
    ``uncertainty_samples`` (2-1000, default 16), ``calibration`` (None: the shipped realistic
    one; "none"; or a file from ``acetab calibrate``), ``seed`` (default 1), ``contours``
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
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: shape {a.shape}, expected {want}")
    return a.tolist()


def _intrinsics(k: Any, name: str) -> Dict[str, float]:
    a = np.asarray(k, dtype=np.float64)
    if a.shape == (3, 3):
        return {"fx": a[0, 0], "fy": a[1, 1], "cx": a[0, 2], "cy": a[1, 2]}
    if a.shape == (4,):
        return dict(zip(("fx", "fy", "cx", "cy"), a.tolist()))
    raise ValueError(f"{name}: shape {a.shape}, expected (4,) fx, fy, cx, cy or a (3, 3) K")


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
        out.append({"points": _float_list(pts, (None, 2), where), "closed": closed})
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
    closed rim), a mapping ``{"points": (N, 2), "closed": bool}``, or a list of those.
    ``template``: ``{"center": (3,), "radius": mm, "axis": (3,)}``, the start placement.
    Options as for ``reconstruct_case``.

    Returns ``vertices`` ((V, 3) float64, mm), ``faces`` ((F, 3) int64), ``cup`` (as in
    ``reconstruct_case``), ``sphere`` (``center``, ``radius``), ``log``, ``views``,
    ``warnings``, ``method``. Writes nothing. Raises AcetabError when the input is refused
    (naming the field) or the reconstruction fails.
    """
    if len(cameras) != len(contours):
        raise ValueError(
            f"{len(cameras)} cameras and {len(contours)} views of contours: one each"
        )
    views = []
    for i, (cam, cs) in enumerate(zip(cameras, contours)):
        v: Dict[str, Any] = {
            "k": _intrinsics(cam["k"], f"cameras[{i}]['k']"),
            "r": _float_list(cam["r"], (3, 3), f"cameras[{i}]['r']"),
            "t": _float_list(cam["t"], (3,), f"cameras[{i}]['t']"),
            "width": int(cam["width"]),
            "height": int(cam["height"]),
            "contours": _contours(cs, f"contours[{i}]"),
        }
        if "name" in cam:
            v["name"] = str(cam["name"])
        views.append(v)
    case = {
        "views": views,
        "template": {
            "center": _float_list(template["center"], (3,), "template['center']"),
            "radius": float(template["radius"]),
            "axis": _float_list(template["axis"], (3,), "template['axis']"),
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
    return _acetab.align(a, b, str(mode), int(samples), float(anchor))


def simulate(
    gt: PathLike,
    levels: Sequence[int] = (1, 3, 5),
    runs: int = 3,
    methods: Sequence[str] = ("srvf",),
    *,
    seed: int = 1,
    protocol: str = "ideal",
    refine_poses: bool = False,
    threads: Optional[int] = None,
    uncertainty_samples: int = 0,
    calibration: Optional[PathLike] = None,
    prior: PathLike = "none",
    cup_estimator: str = "observed-part",
) -> List[Dict[str, Any]]:
    """Run a simulation study on the ground truth ``gt`` ("phantom" or a mesh file, mm).

    Each of ``runs`` runs per noise level (0-5) and method ("srvf", "icp", "icp-normvec" and the
    paper's variants) simulates the X-rays, reconstructs and measures. ``protocol``: "ideal" or
    "realistic" (pose and magnification errors, partial outlines, annotation drift).
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
        "threads": None if threads is None else int(threads),
        "uncertainty_samples": int(uncertainty_samples),
        "calibration": None if calibration is None else os.fspath(calibration),
        "prior": os.fspath(prior),
        "cup_estimator": str(cup_estimator),
    }
    return json.loads(_acetab.simulate_json(json.dumps(opts)))
