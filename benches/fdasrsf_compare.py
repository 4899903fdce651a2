"""Time fdasrsf 2.7.3 and `acetab align` on the same curve pairs and score both results in
fdasrsf's own shape metric, arccos <q1, q2*> (curve_to_q and innerprod_q2 of fdasrsf).

Run through benches/fdasrsf_compare.sh, which makes the virtual environment and builds acetab.
"""
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import fdasrsf.curve_functions as cf

ACETAB = sys.argv[1]


def blob(n, k2=0.3, k3=0.15, ph=0.4, sx=1.0, sy=0.8):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 1 + k2 * np.cos(2 * t) + k3 * np.sin(3 * t + ph)
    return np.vstack([sx * r * np.cos(t), sy * r * np.sin(t)])


def arc(n, bend=1.0, wig=0.3):
    t = np.linspace(0, 3, n)
    return np.vstack([t, np.sin(bend * 2 * t) + wig * t * t])


def transform(b, ang, scale, shift, start=0, warp=0.0):
    n = b.shape[1]
    if warp:
        # Re-parameterise by resampling at uneven parameter values.
        u = np.linspace(0, 1, n, endpoint=False)
        w = u + warp * np.sin(2 * np.pi * u) / (2 * np.pi)
        idx = np.interp(w * n, np.arange(n + 1), np.arange(n + 1)) % n
        lo = np.floor(idx).astype(int)
        f = idx - lo
        b = b[:, lo] * (1 - f) + b[:, (lo + 1) % n] * f
    b = np.roll(b, -start, axis=1)
    c, s = math.cos(ang), math.sin(ang)
    return scale * (np.array([[c, -s], [s, c]]) @ b) + np.array(shift)[:, None]


def score(beta1, beta2_aligned):
    q1 = cf.curve_to_q(beta1)[0]
    q2 = cf.curve_to_q(beta2_aligned)[0]
    return math.acos(max(-1.0, min(1.0, cf.innerprod_q2(q1, q2))))


def pairs():
    # Closed: a blob against a deformed, rotated, re-started and re-parameterised blob.
    yield "closed-1", True, blob(400), transform(blob(400, 0.25, 0.2, 0.9, 1.1), 0.8, 2.0, (5, 1), 90, 0.3)
    yield "closed-2", True, blob(400, 0.1, 0.3), transform(blob(400, 0.2, 0.25, 0.0), -1.9, 0.5, (0, 3), 250, 0.2)
    # Open: an arc against a bent, rotated, re-parameterised one.
    yield "open-1", False, arc(400), transform(arc(400, 1.2, 0.25), 0.6, 1.5, (2, 2))
    yield "open-2", False, arc(400, 0.7, 0.5), transform(arc(400, 0.8, 0.3), -0.4, 0.8, (0, 0))


def write_csv(path, b):
    np.savetxt(path, b.T, delimiter=",", header="x,y", comments="")


def main():
    tmp = tempfile.mkdtemp()
    print(f"{'pair':<10} {'T':>4} {'fdasrsf s':>10} {'acetab s':>10} {'ratio':>8} {'d fdasrsf':>10} {'d acetab':>10}")
    worse = 0
    for name, closed, a, b in pairs():
        for T in (100, 200, 400):
            a_t = cf.resamplecurve(a.copy(), T)
            b_t = cf.resamplecurve(b.copy(), T)
            t0 = time.perf_counter()
            beta2best, q2best, _, _ = cf.find_rotation_and_seed_coord(a_t.copy(), b_t.copy(), closed=1 if closed else 0)
            t_f = time.perf_counter() - t0
            d_f = score(a_t, beta2best)
            pa, pb = os.path.join(tmp, "a.csv"), os.path.join(tmp, "b.csv")
            write_csv(pa, a_t)
            write_csv(pb, b_t)
            mode = "--closed" if closed else "--open"
            out = subprocess.run([ACETAB, "align", pa, pb, mode, "--samples", str(T), "--json"], check=True, capture_output=True, text=True)
            r = json.loads(out.stdout)
            aligned = np.array(r["aligned"]).T
            d_a = score(a_t, aligned) if aligned.shape[1] == T else float("nan")
            worse += d_a > d_f + 1e-9
            print(f"{name:<10} {T:>4} {t_f:>10.4f} {r['seconds']:>10.4f} {t_f / r['seconds']:>8.1f} {d_f:>10.4f} {d_a:>10.4f}")
    print(f"pairs where acetab's distance is above fdasrsf's: {worse}")


main()
