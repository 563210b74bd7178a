#!/usr/bin/env python3
"""Peer of thermode's finite-volume contact model in NumPy/SciPy, for side-by-side timing.

The workload (issue 13): the default fingertip, steady in 23 °C air, touches a 1 cm aluminium slab at 23 °C through
a contact resistance of 1e-3 m²K/W for 90 s, rows every 10 ms, on fv grid levels 0 to 4 (the default grid refined
L times). This script is its own implementation of the same semi-discrete model (thermode-model's fv module: cell
layout, harmonic conductances, perfusion, surface by flux continuity), integrated with SciPy's
solve_ivp(method="BDF") and a sparse Jacobian.

It first checks agreement: thermode at a tight tolerance against this model at a tight tolerance, skin surface
temperature at every row within AGREE_C (1e-6 °C). Then, per level, it measures both solvers' error against this
tight reference, picks the loosest BDF tolerance whose error is at most thermode's at its default tolerance (same
accuracy), and times whole-process runs of both (each writing its CSV), REPEATS paired runs, median. It prints one
markdown row per level: | workload | thermode s | peer s | ratio |; details go to standard error.

Usage: scripts/peer/fv_scipy.py [--levels 0,1,2,3,4] [--repeats 3]
       scripts/peer/fv_scipy.py --run LEVEL --rtol R --out FILE.csv   (one peer run, what is timed)
Environment: THERMODE_BIN, thermode's release binary (default target/release/thermode). Needs numpy and scipy.
"""

import argparse
import csv
import math
import os
import statistics
import subprocess
import sys
import tempfile

import common  # scripts/peer/common.py

try:
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg  # noqa: F401  (sp.linalg.spsolve)
    from scipy.integrate import solve_ivp
except ImportError as missing:
    sys.exit(f"fv_scipy: needs numpy and scipy ({missing}); e.g. python3 -m pip install numpy scipy")

AGREE_C = 1e-6
DURATION_S = 90.0
OUTPUT_DT_S = 0.01
AMBIENT_C = 23.0
OBJECT_C = 23.0
CONTACT_RESISTANCE = 1e-3
TIGHT = 1e-9  # rtol = atol of the reference runs
THERMODE_TIGHT_K = 1e-9  # thermode's local error tolerance of the agreement run
BDF_RTOLS = [1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 3e-8, 1e-8]

# The default fingertip (thermode-model Skin::fingertip): thickness m, k W/mK, rho kg/m3, c J/kgK, perfusion 1/s.
LAYERS = [
    ("epidermis", 0.5e-3, 0.21, 1150.0, 3600.0, 0.0),
    ("dermis", 1.5e-3, 0.37, 1116.0, 3224.0, 0.0),
    ("subcutis", 3.0e-3, 0.16, 971.0, 2303.0, 0.00214),
]
ARTERIAL_C = 36.8
BLOOD_RHO_C = 1060.0 * 3800.0
AIR_W_M2K = 10.0
# Aluminium, the paper's Table 1 in cgs (k cal/(cm s °C), c cal/(g °C), rho g/cm3), 1 cm thick.
CAL = 4.1868
AL_K, AL_RHO, AL_C = 0.526 * CAL * 100.0, 2.70 * 1000.0, 0.215 * CAL * 1000.0
AL_THICKNESS = 0.01
# The default grid: surface cell 10 µm, growth 1.15, largest cell 0.5 mm; level L halves all three (growth excess).
SURFACE_M, GROWTH, MAX_M = 1e-5, 1.15, 5e-4


def stack_cells(surface_m, growth, max_m, thicknesses):
    """Cell widths marching from the contact face, each slab filled exactly (thermode's fv grid rule)."""
    widths, slab, top = [], [], 0.0
    for index, thickness in enumerate(thicknesses):
        first = len(widths)
        covered = 0.0
        while covered < thickness:
            w = min(surface_m + (growth - 1.0) * (top + covered), max_m)
            widths.append(w)
            covered += w
        total = sum(widths[first:])
        last = widths[-1]
        if len(widths) - first > 1 and thickness / (total - last) - 1.0 < 1.0 - thickness / total:
            widths.pop()
            total -= last
        scale = thickness / total
        widths[first:] = [w * scale for w in widths[first:]]
        slab += [index] * (len(widths) - first)
        top += thickness
    return np.array(widths), np.array(slab)


class Model:
    """The fv chain: skin cells deep → surface, then object cells face → far side (a tridiagonal system)."""

    def __init__(self, level):
        f = 0.5**level
        rule = (SURFACE_M * f, 1.0 + (GROWTH - 1.0) * f, MAX_M * f)
        sw, slab = stack_cells(*rule, [l[1] for l in LAYERS])
        ow, _ = stack_cells(*rule, [AL_THICKNESS])
        self.ns, self.no = len(sw), len(ow)
        sk = np.array([LAYERS[i][2] for i in slab])
        scap = np.array([LAYERS[i][3] * LAYERS[i][4] for i in slab]) * sw
        sperf = np.array([LAYERS[i][5] for i in slab]) * BLOOD_RHO_C * sw
        self.slab, self.scap = slab, scap
        ok = np.full(self.no, AL_K)
        ocap = AL_RHO * AL_C * ow
        slink = 1.0 / (0.5 * sw[:-1] / sk[:-1] + 0.5 * sw[1:] / sk[1:])
        olink = 1.0 / (0.5 * ow[:-1] / ok[:-1] + 0.5 * ow[1:] / ok[1:])
        self.r_skin = 0.5 * sw[0] / sk[0]
        self.r_obj = 0.5 * ow[0] / ok[0]
        self.g_contact = 1.0 / (self.r_skin + CONTACT_RESISTANCE + self.r_obj)
        self.g_air = 1.0 / (self.r_skin + 1.0 / AIR_W_M2K)
        n = self.ns + self.no
        # Chain order: skin reversed, then object.
        cap = np.concatenate([scap[::-1], ocap])
        links = np.concatenate([slink[::-1], [self.g_contact], olink])
        diag = np.zeros(n)
        diag[:-1] -= links
        diag[1:] -= links
        perf = np.concatenate([sperf[::-1], np.zeros(self.no)])
        diag -= perf
        self.source = perf * ARTERIAL_C
        self.cap = cap
        self.a_contact = sp.diags([links, diag, links], [-1, 0, 1], format="csc")
        self.n = n

    def surface_index(self):
        return self.ns - 1

    def steady_in_air(self):
        """Skin alone, surface to air: A T + b = 0."""
        ns = self.ns
        a = self.a_contact[:ns, :ns].tolil()
        a[ns - 1, ns - 1] += self.g_contact - self.g_air  # replace the contact link by air
        b = self.source[:ns].copy()
        b[ns - 1] += self.g_air * AMBIENT_C
        skin = sp.linalg.spsolve(a.tocsc(), -b)
        return skin, skin[ns - 1] - self.g_air * (skin[ns - 1] - AMBIENT_C) * self.r_skin

    def outputs(self, y):
        """Rows: surface, object face, heat flux, layer means (y: n × rows)."""
        s0, o0 = y[self.ns - 1], y[self.ns]
        q = self.g_contact * (s0 - o0)
        skin = y[: self.ns][::-1]
        means = [(self.scap[self.slab == i, None] * skin[self.slab == i]).sum(0) / self.scap[self.slab == i].sum()
                 for i in range(len(LAYERS))]
        return s0 - q * self.r_skin, o0 + q * self.r_obj, q, means


def run_peer(level, rtol, out_path=None):
    m = Model(level)
    skin, surface0 = m.steady_in_air()
    y0 = np.concatenate([skin, np.full(m.no, OBJECT_C)])
    rows = int(math.ceil(DURATION_S / OUTPUT_DT_S - 1e-9))
    t_eval = np.arange(1, rows + 1) * OUTPUT_DT_S
    t_eval[-1] = DURATION_S
    jac = sp.diags(1.0 / m.cap) @ m.a_contact
    jac = jac.tocsc()
    inv_cap, source = 1.0 / m.cap, m.source

    def rhs(_t, y):
        return (jac @ y) + source * inv_cap

    sol = solve_ivp(rhs, (0.0, DURATION_S), y0, method="BDF", t_eval=t_eval, rtol=rtol, atol=rtol,
                    jac=jac, first_step=1e-6)
    if not sol.success:
        raise RuntimeError(sol.message)
    surface, face, flux, means = m.outputs(sol.y)
    surface = np.concatenate([[surface0], surface])
    if out_path:
        with open(out_path, "w") as f:
            f.write("time_s,skin_surface_c,epidermis_mean_c,dermis_mean_c,subcutis_mean_c,object_face_c,heat_flux_w_m2\n")
            times = np.concatenate([[0.0], t_eval])
            face = np.concatenate([[OBJECT_C], face])
            flux = np.concatenate([[math.nan], flux])
            means = [np.concatenate([[math.nan], mm]) for mm in means]
            for k in range(len(times)):
                f.write(f"{times[k]!r},{surface[k]!r},{means[0][k]!r},{means[1][k]!r},{means[2][k]!r},"
                        f"{face[k]!r},{flux[k]!r}\n")
    return surface, sol.nfev, sol.nlu, m.ns + m.no


def thermode_bin():
    path = os.environ.get("THERMODE_BIN", "target/release/thermode")
    if not os.access(path, os.X_OK):
        sys.exit(f"fv_scipy: no thermode binary at {path} (build with cargo build --release, or set THERMODE_BIN)")
    return path


def thermode_cmd(level, out, tolerance=None):
    cmd = [thermode_bin(), "simulate", "--model", "fv", "--material", "aluminium", "--contact-resistance",
           str(CONTACT_RESISTANCE), "--duration", str(DURATION_S), "--dt", str(OUTPUT_DT_S), "--ambient",
           str(AMBIENT_C), "--fv-level", str(level), "--out", out]
    if tolerance is not None:
        cmd += ["--fv-tolerance", repr(tolerance)]
    return cmd


def thermode_surface(level, tolerance=None):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "fv.csv")
        subprocess.run(thermode_cmd(level, out, tolerance), check=True, capture_output=True)
        with open(out) as f:
            return np.array([float(r["skin_surface_c"]) for r in csv.DictReader(f)])


def main():
    parser = common.parser(__doc__)
    parser.add_argument("--levels", default="0,1,2,3,4")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--run", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--rtol", type=float, default=1e-6, help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.run is not None:
        run_peer(args.run, args.rtol, args.out)
        return
    levels = [int(x) for x in args.levels.split(",")]
    log = lambda *a: print(*a, file=sys.stderr, flush=True)
    rows = []
    for level in levels:
        reference, ref_nfev, _, cells = run_peer(level, TIGHT)
        tight = thermode_surface(level, THERMODE_TIGHT_K)
        agree = float(np.max(np.abs(tight - reference)))
        log(f"level {level} ({cells} cells): thermode (tolerance {THERMODE_TIGHT_K} K) vs BDF (rtol = atol = {TIGHT}):"
            f" max |Δ surface| {agree:.2e} °C over {len(reference)} rows (BDF {ref_nfev} evaluations)")
        if not agree <= AGREE_C:
            sys.exit(f"fv_scipy: level {level}: thermode and the peer disagree by {agree} °C > {AGREE_C} °C")
        error_thermode = float(np.max(np.abs(thermode_surface(level) - reference)))
        chosen = None
        for rtol in BDF_RTOLS:
            surface, nfev, nlu, _ = run_peer(level, rtol)
            error = float(np.max(np.abs(surface - reference)))
            if error <= error_thermode:
                chosen = (rtol, error, nlu, nfev)
                break
        if chosen is None:
            sys.exit(f"fv_scipy: level {level}: no BDF tolerance down to {BDF_RTOLS[-1]} reaches thermode's error")
        rtol, error_peer, nlu, nfev = chosen
        with tempfile.TemporaryDirectory() as tmp:
            out_t, out_p = os.path.join(tmp, "t.csv"), os.path.join(tmp, "p.csv")
            peer_cmd = [sys.executable, os.path.abspath(__file__), "--run", str(level), "--rtol", repr(rtol),
                        "--out", out_p]
            pairs = [(common.timed(thermode_cmd(level, out_t)), common.timed(peer_cmd)) for _ in range(args.repeats)]
        t_s = statistics.median(p[0] for p in pairs)
        p_s = statistics.median(p[1] for p in pairs)
        log(f"level {level}: thermode error {error_thermode:.2e} °C at its default tolerance; BDF rtol = atol = {rtol}"
            f" error {error_peer:.2e} °C with {nfev} evaluations, {nlu} LU factorisations; median of {args.repeats} paired runs")
        rows.append(f"| fv aluminium R_c 1e-3 90 s, level {level} ({cells} cells) | {t_s:.3f} | {p_s:.3f} | {p_s / t_s:.1f} |")
        print(rows[-1], flush=True)


if __name__ == "__main__":
    main()
