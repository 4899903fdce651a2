"""Can a population shape prior tell the cup from what three outlines see? (issue 17)

An offline experiment on the 47 acetabula in ../shared/data (LibHip cartilage shells, MIT; JHU
I-STAR pelvis atlas bone-side acetabula, CC BY 4.0, Han R, Uneri A, et al., Phys. Med. Biol. 64
(2019) 095022), leave-one-subject-out (both hips of a subject leave together). No reconstruction
is involved: each truth's "seen" vertices are those the default views (AP and +-20 degrees about
the long axis) can outline: vertices whose normal is within 12 degrees of perpendicular to a view
direction, and the border. The question is how well the truth's cup (the sphere of all its
vertices) follows from the seen vertices alone, with and without learned knowledge:

  plain      the sphere fitted to the seen vertices
  shape      a sphere plus the population's mean radial deviation (and K principal modes,
             Gaussian prior) fitted to the seen vertices; deviation fields on 1600 directions,
             4-degree kernel, in body axes (x mirrored so every hip opens to -x) or in an
             acetabular frame (opening axis, long axis projected)

Run: python3 docs/experiments/shape_prior.py [../shared/data]   (needs numpy; ~10 s)
"""
import glob, os, sys, warnings
import numpy as np

DATA = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "../../../shared/data")


def read_stl(p):
    tris, cur = [], []
    for line in open(p):
        t = line.split()
        if t and t[0] == "vertex":
            cur.append([float(x) for x in t[1:4]])
        if len(cur) == 3:
            tris.append(cur)
            cur = []
    v, inv = np.unique(np.array(tris).reshape(-1, 3).round(6), axis=0, return_inverse=True)
    return v, inv.reshape(-1, 3)


def fit_sphere(p):
    a = np.c_[2 * p, np.ones(len(p))]
    x, *_ = np.linalg.lstsq(a, (p**2).sum(1), rcond=None)
    c, r = x[:3], np.sqrt(x[3] + x[:3] @ x[:3])
    for _ in range(20):
        d = p - c
        l = np.linalg.norm(d, axis=1)
        j = np.c_[-d / l[:, None], -np.ones(len(p))]
        dx, *_ = np.linalg.lstsq(j, -(l - r), rcond=None)
        c, r = c + dx[:3], r + dx[3]
    return c, r


def edges(f):
    e = {}
    for t in f:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            k = (min(a, b), max(a, b))
            e[k] = e.get(k, 0) + 1
    return e


def truth(p):
    """The ground-truth surface as `acetab` takes it: a closed shell's outer side."""
    v, f = read_stl(p)
    if all(n == 2 for n in edges(f).values()):
        c, _ = fit_sphere(v)
        a, b, d = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        f = f[(np.cross(b - a, d - a) * ((a + b + d) / 3 - c)).sum(1) > 0]
        used = np.unique(f)
        remap = np.full(v.shape[0], -1)
        remap[used] = np.arange(len(used))
        v, f = v[used], remap[f]
    return v, f


def seen(v, f):
    n = np.zeros_like(v)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    n /= np.linalg.norm(n, axis=1)[:, None] + 1e-12
    sel = np.zeros(len(v), bool)
    for deg in (0, 20, -20):
        t = np.radians(deg)
        sel |= abs(n @ np.array([-np.sin(t), np.cos(t), 0])) < np.sin(np.radians(12))
    for (a, b), cnt in edges(f).items():
        if cnt == 1:
            sel[a] = sel[b] = True
    return v[sel]


N = 1600
_i = np.arange(N) + 0.5
_phi, _th = np.arccos(1 - 2 * _i / N), np.pi * (1 + 5**0.5) * _i
GRID = np.c_[np.cos(_th) * np.sin(_phi), np.sin(_th) * np.sin(_phi), np.cos(_phi)]
SIGMA, MIN_WEIGHT = np.radians(4), 0.1


def kernel(w):
    return np.exp(-(np.arccos(np.clip(w @ GRID.T, -1, 1)) ** 2) / (2 * SIGMA**2))


def field(v, c, r, rot):
    d = (v - c) @ rot.T
    l = np.linalg.norm(d, axis=1)
    k = kernel(d / l[:, None])
    s = k.sum(0)
    out = (k * ((l - r) / r)[:, None]).sum(0) / np.maximum(s, 1e-12)
    out[s < MIN_WEIGHT] = np.nan
    return out


def interp(values, w):
    k = kernel(w)[:, ~np.isnan(values)]
    s = k.sum(1)
    return (k * values[~np.isnan(values)]).sum(1) / np.maximum(s, 1e-12) * (s > MIN_WEIGHT)


def fit_shape(p, rot, mean, modes, sd):
    c, r = fit_sphere(p)
    b = np.zeros(len(modes))
    for _ in range(30):
        d = (p - c) @ rot.T
        l = np.linalg.norm(d, axis=1)
        w = d / l[:, None]
        ph = np.array([interp(m, w) for m in modes]).T if len(modes) else np.zeros((len(p), 0))
        shape = 1 + interp(mean, w) + ph @ b
        res = np.r_[l - r * shape, b / sd]
        j = np.c_[-(d / l[:, None]) @ rot, -shape[:, None], -r * ph]
        j = np.r_[j, np.c_[np.zeros((len(b), 4)), np.diag(1 / sd)]]
        dx, *_ = np.linalg.lstsq(j, -res, rcond=None)
        c, r, b = c + dx[:3], r + dx[3], b + dx[4:]
        if np.linalg.norm(dx) < 1e-7:
            break
    return 2 * r


def frame(v, c, acetabular):
    opening = c - v.mean(0)
    opening /= np.linalg.norm(opening)
    mirror = np.diag([-1.0, 1, 1]) if opening[0] > 0 else np.eye(3)
    if not acetabular:
        return mirror
    e1 = mirror @ opening
    e2 = np.array([0, 0, 1.0]) - e1[2] * e1
    e2 /= np.linalg.norm(e2)
    return np.array([e1, e2, np.cross(e1, e2)]) @ mirror


files = sorted(glob.glob(DATA + "/acetabula/*.stl")) + sorted(glob.glob(DATA + "/pelvis-atlas/acetabula/*.stl"))
if not files:
    sys.exit(f"no meshes under {DATA}")
meshes = {}
for f in files:
    name = os.path.basename(f).replace("_ac_wo_gap", "").replace(".stl", "")
    v, fa = truth(f)
    c, r = fit_sphere(v)
    meshes[name] = dict(v=v, c=c, r=r, seen=seen(v, fa))
subject = lambda m: m.split("_")[0]


def report(label, errors):
    for pop, tag in (("shells", "m"), ("atlas", "a")):
        e = np.array([x for m, x in errors.items() if m.startswith(tag)])
        truth_d = np.array([2 * meshes[m]["r"] for m in errors if m.startswith(tag)])
        exact = np.mean(np.round((truth_d + e) / 2) == np.round(truth_d / 2))
        print(f"{label:44} {pop:6} bias {e.mean():+.2f}  RMS {np.sqrt((e**2).mean()):.2f}  "
              f"|e|<=1 {np.mean(abs(e) <= 1):4.0%}  exact size {exact:4.0%}")


plain = {m: 2 * fit_sphere(d["seen"])[1] - 2 * d["r"] for m, d in meshes.items()}
report("plain sphere of the seen vertices", plain)
for pooled in (True, False):
    corrected = {}
    for m in meshes:
        train = [n for n in meshes if subject(n) != subject(m) and (pooled or n[0] == m[0])]
        corrected[m] = plain[m] - np.mean([plain[n] for n in train])
    report(f"plain, LOSO bias removed ({'pooled' if pooled else 'per population'})", corrected)
for acetabular in (False, True):
    for d in meshes.values():
        d["rot"] = frame(d["v"], d["c"], acetabular)
        d["field"] = field(d["v"], d["c"], d["r"], d["rot"])
    for pooled in (True, False):
        for k in (0, 2):
            errors = {}
            for m, d in meshes.items():
                train = [n for n in meshes if subject(n) != subject(m) and (pooled or n[0] == m[0])]
                fields = np.array([meshes[n]["field"] for n in train])
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    mean = np.nan_to_num(np.nanmean(fields, 0))
                x = np.where(np.isnan(fields), mean, fields) - mean
                _, s, vt = np.linalg.svd(x, full_matrices=False)
                errors[m] = fit_shape(d["seen"], d["rot"], mean, vt[:k], s[:k] / np.sqrt(len(train) - 1)) - 2 * d["r"]
            where = "acetabular frame" if acetabular else "body axes"
            report(f"shape prior, {where}, K={k}, {'pooled' if pooled else 'per pop.'}", errors)
