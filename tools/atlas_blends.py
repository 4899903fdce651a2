"""New bone-side acetabula from the pelvis atlas's vertex correspondences, for checking the method
on acetabula it has not seen (docs/population.md, "Acetabula made from the atlas's correspondences").

The atlas's hemipelves (../shared/data/pelvis-atlas/hemipelves, CC BY 4.0, Han et al., Phys. Med.
Biol. 64 (2019) 095022) share their vertices across subjects of one side. For each subject A of a
side and the next subject B in number order (the last with the first), B is moved rigidly onto A
(least squares over all 5,000 vertices, no scale) and the two are mixed vertex by vertex,
V = (1 - t) A + t B, with t = 0.5 (between the two: "i<A><B>") for every other pair and t = -0.4 (A
pushed away from B, a shape beyond the atlas's: "e<A><B>") for the rest. Each mix is cut by the
atlas's own extract_acetabulum.py, which drops a cut with a radius outside 21-32 mm or too few faces,
as it drops atlas members. The file names (i0204_lhip.stl, ...) keep the side and give each mix its
own subject, so leave-one-subject-out studies treat them as new subjects.

Other sets of acetabula the project has not seen come from other partners and other shares:
--step K pairs each subject with the K-th next one (default 1), --mix T_EVEN,T_ODD sets t for the
even and odd pairs (default 0.5,-0.4; a positive t names a mix "i", a negative one "e").

Nothing is written into the repository: OUT_DIR is for scratch studies.
Usage: python3 tools/atlas_blends.py [--step K] [--mix T_EVEN,T_ODD] OUT_DIR [ATLAS_DIR]
(ATLAS_DIR: ../shared/data/pelvis-atlas). Needs numpy."""
import argparse
import importlib.util
import os
import subprocess
import sys

import numpy as np

MIX = (0.5, -0.4)  # t for even and odd pairs in a side's list


def extractor(atlas):
    """The atlas's own extract_acetabulum.py as a module: its VTK reader, and the cut it makes."""
    spec = importlib.util.spec_from_file_location(
        "extract_acetabulum", os.path.join(atlas, "extract_acetabulum.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_vtk(path, V, F):
    with open(path, "w") as out:
        out.write("# vtk DataFile Version 3.0\nmixed hemipelvis\nASCII\nDATASET POLYDATA\n")
        out.write(f"POINTS {len(V)} float\n")
        for v in V:
            out.write(f"{v[0]:.5f} {v[1]:.5f} {v[2]:.5f}\n")
        out.write(f"POLYGONS {len(F)} {4 * len(F)}\n")
        for f in F:
            out.write(f"3 {f[0]} {f[1]} {f[2]}\n")


def onto(A, B):
    """B moved rigidly onto A (Kabsch: the rotation and shift of least squared distance)."""
    ca, cb = A.mean(0), B.mean(0)
    U, _, Vt = np.linalg.svd((B - cb).T @ (A - ca))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    return (B - cb) @ R.T + ca


def mixes(atlas, step=1, mix=MIX):
    """(name, vertices, faces) of every mix, side by side, of the members whose acetabulum the atlas
    kept (a25_lhip's correspondence failed: it has no acetabulum and takes no part): each member A
    with the `step`-th next member B of its side, t = mix[0] for the even pairs, mix[1] for the
    odd ones."""
    load_vtk = extractor(atlas).load_vtk
    hemipelves, acetabula = (os.path.join(atlas, d) for d in ("hemipelves", "acetabula"))
    kept = {f[:-4] for f in os.listdir(acetabula) if f.endswith(".stl")}
    names = sorted(f[:-4] for f in os.listdir(hemipelves) if f.endswith(".vtk") and f[:-4] in kept)
    for side in ("lhip", "rhip"):
        subjects = [n.split("_")[0][1:] for n in names if n.endswith("_" + side)]
        for k, a in enumerate(subjects):
            b = subjects[(k + step) % len(subjects)]
            if b == a:
                sys.exit(f"--step {step} pairs a{a}_{side} with itself ({len(subjects)} members)")
            VA, F = load_vtk(os.path.join(hemipelves, f"a{a}_{side}.vtk"))
            VB, FB = load_vtk(os.path.join(hemipelves, f"a{b}_{side}.vtk"))
            if VA.shape != VB.shape or not np.array_equal(F, FB):
                sys.exit(f"a{a}_{side} and a{b}_{side} do not share their vertices and faces")
            t = mix[k % 2]
            tag = "i" if t > 0 else "e"
            yield f"{tag}{a}{b}_{side}", (1 - t) * VA + t * onto(VA, VB), F


def arguments(argv):
    """OUT_DIR, ATLAS_DIR, the step and the two shares, checked: a step that pairs no member with
    another, or a share that is 0 (A itself) or 1 (B itself), is refused."""
    here = os.path.dirname(os.path.abspath(__file__))
    parser = argparse.ArgumentParser(description="Acetabula mixed from the pelvis atlas's members.")
    parser.add_argument("out")
    parser.add_argument("atlas", nargs="?",
                        default=os.path.join(here, "..", "..", "shared", "data", "pelvis-atlas"))
    parser.add_argument("--step", type=int, default=1)
    parser.add_argument("--mix", default=",".join(str(t) for t in MIX))
    args = parser.parse_args(argv)
    try:
        mix = tuple(float(t) for t in args.mix.split(","))
    except ValueError:
        parser.error(f"--mix {args.mix!r}: two numbers, T_EVEN,T_ODD")
    if len(mix) != 2 or any(not np.isfinite(t) or t in (0.0, 1.0) for t in mix):
        parser.error(f"--mix {args.mix!r}: two finite shares, neither 0 nor 1")
    if args.step < 1:
        parser.error(f"--step {args.step}: at least 1")
    return os.path.abspath(args.out), args.atlas, args.step, mix


def main():
    out, atlas, step, mix = arguments(sys.argv[1:])
    hemipelves = os.path.join(atlas, "hemipelves")
    script = os.path.join(atlas, "extract_acetabulum.py")
    if not os.path.isdir(hemipelves) or not os.path.isfile(script):
        sys.exit(f"{atlas}: no hemipelves/ folder or extract_acetabulum.py (the shared pelvis atlas)")
    mixed = os.path.join(out, "hemipelves")
    os.makedirs(mixed, exist_ok=True)
    paths = []
    for name, V, F in mixes(atlas, step, mix):
        path = os.path.join(mixed, name + ".vtk")
        write_vtk(path, V, F)
        paths.append(path)
    # The atlas's own cut, its own rules for what it drops.
    subprocess.run([sys.executable, script, out, *paths], check=True)


if __name__ == "__main__":
    main()
