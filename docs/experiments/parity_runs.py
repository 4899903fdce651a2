"""How much of issue 16's level-5 parity bar is the runs' spread? (stop 68)

The bar: on every acetabulum, srvf's mean MAE at level 5 at most 1.05x the better baseline's
(icp, icp-normvec), each mean read from three runs. This script reads several level-5 sweeps of
the same 47 acetabula that differ only in the study seed (each `acetab simulate --gt
../shared/data/acetabula ../shared/data/pelvis-atlas/acetabula --levels 5 --runs 3 --methods
srvf,icp,icp-normvec --seed S --threads 2 --uncertainty-samples 0 --out DIR_S`; a population
check's folder does too, its level-5 rows are read) and prints, per sweep, the acetabula over the
bar; over the sweeps pooled (3 runs x sweeps a side, paired case by case), the acetabula over it
with their mean MAE, the MAE with the result's translation taken out (`shifted_mae_mm`), the
translation's length and its component along the views' mean direction (`depth_offset_mm`,
before the calibration's offset); how often srvf of one sweep is over 1.05x srvf of another, and
over the better of two other sweeps' srvf (unpaired: other cases); and how many acetabula a
check of three runs a side is expected to find over the bar from the runs' spread alone: each
acetabulum's three runs drawn (with replacement) from its pooled runs, srvf's MAE with each
other method's of the same case, 2,000 draws of the whole check (random seed 68), with srvf's
MAE as it is and scaled down by a few per cent (what an srvf that much better would read).

Data: the 8 LibHip cartilage shells (MIT) and 39 JHU I-STAR pelvis-atlas acetabula (CC BY 4.0,
Han R, Uneri A, et al., Phys. Med. Biol. 64 (2019) 095022) in ../shared/data.

With `--srvf SDIR_7 SDIR_8 ...` (one folder per DIR, the same seeds in the same order) srvf's rows
are read from those sweeps instead (`--methods srvf` sweeps of a variant: other outlines, other
settings) and the baselines' from the DIRs, so a variant of srvf meets the same baseline runs
(stop 69: srvf fed outlines without the 2 px noise). Runs are paired by seed and run number:
the same simulated X-rays where the variant ran the same protocol, otherwise only the same
acetabulum (a variant of another protocol draws other outlines). The expected count is also
printed with srvf's three-run mean replaced by its pooled mean (no run spread of its own), so
that what srvf's spread adds to the count and what the baselines' spread adds can be told apart.

Per sweep it also reads the bar for each method in turn (its mean MAE over 1.05x the better of
the other two) and srvf's against each baseline alone; and over the sweeps, srvf's and
icp-normvec's runs of the same case paired, whether the result nearer its observed outlines
(`outline_px`) is the more accurate one (stop 71: a score the X-rays give to choose between them).

Run: python3 docs/experiments/parity_runs.py DIR_7 DIR_8 DIR_9 ... [--srvf SDIR_7 SDIR_8 ...]
(standard library only)
"""
import csv
import itertools
import math
import os
import random
import statistics as st
import sys

METHODS = ("srvf", "icp", "icp-normvec")
BAR = 1.05


def load(folder):
    """(mesh, method) -> level-5 rows of one sweep."""
    out = {}
    for mesh in sorted(os.listdir(folder)):
        path = os.path.join(folder, mesh, "runs.csv")
        if not os.path.isfile(path):
            continue
        for row in csv.DictReader(open(path)):
            if row["level"] == "5" and row["method"] in METHODS and not row["error"]:
                out.setdefault((mesh, row["method"]), []).append(row)
    return out


def mean(rows, key="mae_mm"):
    return st.mean(float(r[key]) for r in rows)


def paired_runs(sweeps, mesh):
    """Per case (sweep, run), the three methods' MAEs."""
    out = []
    for s in sweeps:
        by = {k: {r["run"]: float(r["mae_mm"]) for r in s[(mesh, k)]} for k in METHODS}
        out += [
            tuple(by[k][run] for k in METHODS)
            for run in by["srvf"]
            if all(run in by[k] for k in METHODS)
        ]
    return out


def expected_over(cases, scale, draws=2000, seed=68, srvf_spread=True):
    """Mean count of acetabula over the bar in a three-run check drawn from the pooled runs
    (`cases`: each acetabulum's `paired_runs`; without `srvf_spread`, srvf's three-run mean is
    its pooled mean)."""
    rng = random.Random(seed)
    meshes = list(cases)
    pooled_srvf = {m: st.mean(p[0] for p in cases[m]) for m in meshes}
    total = 0
    for _ in range(draws):
        for m in meshes:
            pick = [rng.choice(cases[m]) for _ in range(3)]
            srvf = scale * (st.mean(p[0] for p in pick) if srvf_spread else pooled_srvf[m])
            total += srvf > BAR * min(st.mean(p[1] for p in pick), st.mean(p[2] for p in pick))
    return total / draws


def ratio(sweeps, mesh):
    """srvf's mean MAE over the better baseline's, the given sweeps pooled."""
    pooled = {k: [r for s in sweeps for r in s[(mesh, k)]] for k in METHODS}
    return mean(pooled["srvf"]) / min(mean(pooled["icp"]), mean(pooled["icp-normvec"])), pooled


def each_over(sweep, meshes):
    """Per method, the acetabula where its mean MAE is over the bar times the better of the other
    two methods' (the bar read for each method in turn); then srvf against each baseline alone."""
    mu = [{k: mean(sweep[(m, k)]) for k in METHODS} for m in meshes]
    each = {
        k: sum(x[k] > BAR * min(x[o] for o in METHODS if o != k) for x in mu) for k in METHODS
    }
    alone = {k: sum(x["srvf"] > BAR * x[k] for x in mu) for k in METHODS[1:]}
    return each, alone


def outline_score(sweeps, meshes):
    """srvf's and icp-normvec's runs of the same case paired: the correlation of the difference of
    their distance to the observed outlines (`outline_px`) with the difference of their MAE, the
    share of pairs where the result nearer its outlines is the more accurate one, and the count."""
    d_px, d_mae = [], []
    for s in sweeps:
        for m in meshes:
            other = {r["run"]: r for r in s[(m, "icp-normvec")]}
            for r in s[(m, "srvf")]:
                o = other.get(r["run"])
                if o is None:
                    continue
                px = float(r["outline_px"]) - float(o["outline_px"])
                if math.isfinite(px):
                    d_px.append(px)
                    d_mae.append(float(r["mae_mm"]) - float(o["mae_mm"]))
    if len(d_px) < 2:
        return float("nan"), float("nan"), len(d_px)
    agree = sum((a < 0) == (b < 0) for a, b in zip(d_px, d_mae)) / len(d_px)
    return st.correlation(d_px, d_mae), agree, len(d_px)


def with_srvf_from(sweep, variant):
    """`sweep` with its srvf rows replaced by `variant`'s."""
    out = {k: v for k, v in sweep.items() if k[1] != "srvf"}
    out.update({k: v for k, v in variant.items() if k[1] == "srvf"})
    return out


def main(folders, srvf_folders=None):
    sweeps = [load(f) for f in folders]
    labels = [os.path.basename(os.path.normpath(f)) for f in folders]
    if srvf_folders:
        sweeps = [with_srvf_from(s, load(v)) for s, v in zip(sweeps, srvf_folders)]
        labels = [f"{a} (srvf: {os.path.normpath(v)})" for a, v in zip(labels, srvf_folders)]
    meshes = sorted(
        {m for m, _ in sweeps[0]}.intersection(*({m for m, _ in s} for s in sweeps[1:]))
    )
    meshes = [m for m in meshes if all((m, k) in s for s in sweeps for k in METHODS)]
    print(f"{len(meshes)} acetabula in all {len(folders)} sweeps")
    for label, s in zip(labels, sweeps):
        each = ((m, ratio([s], m)[0]) for m in meshes)
        over = [f"{m} {r:.3f}" for m, r in each if r > BAR]
        print(f"{label}: {len(over)} over {BAR}x: {', '.join(over)}")
        counts, alone = each_over(s, meshes)
        print(
            f"  each method over {BAR}x the better of the other two: "
            + ", ".join(f"{k} {n}" for k, n in counts.items())
            + f"; srvf over {BAR}x one baseline: "
            + ", ".join(f"{k} {n}" for k, n in alone.items())
        )
    pooled = {m: ratio(sweeps, m) for m in meshes}
    ratios = sorted(((pooled[m][0], m) for m in meshes), reverse=True)
    runs = 3 * len(sweeps)
    over = [(r, m) for r, m in ratios if r > BAR]
    print(
        f"pooled ({runs} runs a side): {len(over)} over {BAR}x; mean ratio "
        f"{st.mean(r for r, _ in ratios):.3f}, median {st.median(r for r, _ in ratios):.3f}"
    )
    for r, m in ratios[: max(len(over), 5)]:
        cells = []
        for k in METHODS:
            rows = pooled[m][1][k]
            depth = (
                mean(rows, "depth_offset_mm") if rows[0].get("depth_offset_mm") else float("nan")
            )
            cells.append(
                f"{k} {mean(rows):.3f} (shift-free {mean(rows, 'shifted_mae_mm'):.3f}, "
                f"shift {mean(rows, 'frame_shift_mm'):.2f}, depth {depth:+.2f})"
            )
        print(f"  {m} {r:.3f}: " + "; ".join(cells))
    if len(sweeps) >= 3:
        srvf = [{m: mean(s[(m, "srvf")]) for m in meshes} for s in sweeps]
        one, two = [], []
        for a in range(len(sweeps)):
            rest = [b for b in range(len(sweeps)) if b != a]
            for b in rest:
                one.append(sum(srvf[a][m] > BAR * srvf[b][m] for m in meshes))
            for b, c in itertools.combinations(rest, 2):
                two.append(sum(srvf[a][m] > BAR * min(srvf[b][m], srvf[c][m]) for m in meshes))
        print(
            f"srvf of one sweep over {BAR}x srvf of another: {min(one)}-{max(one)} acetabula, "
            f"mean {st.mean(one):.1f}; over the better of two others: {min(two)}-{max(two)}, "
            f"mean {st.mean(two):.1f}"
        )
    corr, agree, n = outline_score(sweeps, meshes)
    print(
        f"srvf and icp-normvec run by run ({n} pairs): the difference of their outline_px "
        f"correlates {corr:.2f} with that of their MAE; the result nearer its outlines is the "
        f"more accurate in {100 * agree:.0f} %"
    )
    cases = {m: paired_runs(sweeps, m) for m in meshes}
    cells = [f"x{scale}: {expected_over(cases, scale):.2f}" for scale in (1.0, 0.95, 0.9, 0.86)]
    print(
        f"expected over {BAR}x in a check of 3 runs a side (srvf's MAE scaled): " + ", ".join(cells)
    )
    cells = [
        f"x{scale}: {expected_over(cases, scale, srvf_spread=False):.2f}"
        for scale in (1.0, 0.95, 0.9, 0.86)
    ]
    print("  the same with srvf at its pooled mean (no run spread of its own): " + ", ".join(cells))


if __name__ == "__main__":
    args = sys.argv[1:]
    variant = None
    if "--srvf" in args:
        at = args.index("--srvf")
        args, variant = args[:at], args[at + 1 :]
        if len(variant) != len(args):
            sys.exit(
                f"--srvf takes one folder per sweep: {len(args)} sweeps, "
                f"{len(variant)} srvf folders"
            )
    if not args:
        sys.exit(__doc__)
    main(args, variant)
