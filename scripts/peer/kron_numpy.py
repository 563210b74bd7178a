#!/usr/bin/env python3
"""Peer of thermode's kron contact simulation in plain Python and in NumPy, for side-by-side timing.

The workload (issue 13): the default fingertip (three layers: epidermis 0.5 mm, dermis 1.5 mm, subcutis 3 mm,
perfused in the subcutis), steady in 23 °C air, touches a 1 cm aluminium slab at 23 °C for 90 s, stepped by
backward Euler at 1 ms, every step written as a CSV row (time, T1, T2, T3, heat flux). thermode's `simulate --model
kron --dt 0.001 --duration 90 --out FILE` writes the same rows plus two display columns (the eq. 7 set-point and
its finger model), which this peer does not compute: the comparison favours the peer a little.

Two peers, each its own implementation of the model in thermode-model's kron module (the same conductances,
perfusion and backward-Euler system):
- `python`: a plain Python loop solving the 3x3 system per step, rows written with the csv module;
- `numpy`: the same linear time-invariant recurrence T_p = Phi T_(p-1) + g evaluated for all steps at once from the
  eigen-decomposition of Phi, rows written with numpy.savetxt.

It first checks agreement with thermode's CSV (T1, T2, T3 and the flux at every row within AGREE_C = 1e-9), then
times whole-process runs (median of REPEATS paired runs) and prints markdown rows
`| workload | thermode s | peer s | ratio |`.

Usage: scripts/peer/kron_numpy.py [--repeats 5]
       scripts/peer/kron_numpy.py --run python|numpy --out FILE.csv   (one peer run, what is timed)
Environment: THERMODE_BIN, thermode's release binary (default target/release/thermode). Needs numpy.
"""

import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile

import common  # scripts/peer/common.py

try:
    import numpy as np
except ImportError as missing:
    sys.exit(f"kron_numpy: needs numpy ({missing}); e.g. python3 -m pip install numpy")

AGREE_C = 1e-9
DURATION_S = 90.0
DT_S = 1e-3
AMBIENT_C = 23.0
# The default fingertip (thermode-model skin.rs) and blood.
LAYERS = [  # thickness m, k W/(m K), rho kg/m3, c J/(kg K), perfusion 1/s
    (0.5e-3, 0.21, 1150.0, 3600.0, 0.0),
    (1.5e-3, 0.37, 1116.0, 3224.0, 0.0),
    (3.0e-3, 0.16, 971.0, 2303.0, 0.00214),
]
ARTERIAL_C, BLOOD_RHO, BLOOD_C, AIR_W_M2K = 36.8, 1060.0, 3800.0, 10.0


def thermode_bin():
    return os.environ.get("THERMODE_BIN", "target/release/thermode")


def aluminium():
    out = subprocess.run([thermode_bin(), "materials", "--format", "json"], check=True, capture_output=True, text=True)
    return next(m for m in json.loads(out.stdout) if m["name"] == "aluminium")


def system(g_env, t_env):
    """A (3x3) and b of C dT/dt = A T + b, and the capacities C."""
    dx = [l[0] for l in LAYERS]
    k = [l[1] for l in LAYERS]
    cap = [l[0] * l[2] * l[3] for l in LAYERS]
    g12 = 2.0 / (dx[0] / k[0] + dx[1] / k[1])
    g23 = 2.0 / (dx[1] / k[1] + dx[2] / k[2])
    p = [l[4] * BLOOD_RHO * BLOOD_C * l[0] for l in LAYERS]
    a = [[-(g_env + g12) - p[0], g12, 0.0], [g12, -(g12 + g23) - p[1], g23], [0.0, g23, -g23 - p[2]]]
    b = [p[0] * ARTERIAL_C + g_env * t_env, p[1] * ARTERIAL_C, p[2] * ARTERIAL_C]
    return a, b, cap


def contact_conductance(material):
    dx1, k1 = LAYERS[0][0], LAYERS[0][1]
    return 2.0 / (dx1 / k1 + material["thickness_m"] / material["conductivity_w_mk"])


def solve3(m, r):
    """Gaussian elimination of a 3x3 tridiagonal system (Thomas), in plain Python."""
    c0 = m[0][1] / m[0][0]
    d0 = r[0] / m[0][0]
    den1 = m[1][1] - m[1][0] * c0
    c1 = m[1][2] / den1
    d1 = (r[1] - m[1][0] * d0) / den1
    den2 = m[2][2] - m[2][1] * c1
    x2 = (r[2] - m[2][1] * d1) / den2
    x1 = d1 - c1 * x2
    return [d0 - c0 * x1, x1, x2]


def initial_state():
    a, b, _ = system(AIR_W_M2K, AMBIENT_C)
    return solve3([[-v for v in row] for row in a], b)


def run_python(material, out_path):
    g = contact_conductance(material)
    a, b, cap = system(g, AMBIENT_C)
    m = [[(cap[i] if i == j else 0.0) - DT_S * a[i][j] for j in range(3)] for i in range(3)]
    t = initial_state()
    steps = round(DURATION_S / DT_S)
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_s", "t1_c", "t2_c", "t3_c", "heat_flux_w_m2"])
        w.writerow([0.0, t[0], t[1], t[2], AIR_W_M2K * (t[0] - AMBIENT_C)])
        for p in range(1, steps + 1):
            t = solve3(m, [cap[i] * t[i] + DT_S * b[i] for i in range(3)])
            w.writerow([p * DT_S, t[0], t[1], t[2], g * (t[0] - AMBIENT_C)])


def run_numpy(material, out_path):
    g = contact_conductance(material)
    a, b, cap = system(g, AMBIENT_C)
    a, b, cap = np.array(a), np.array(b), np.array(cap)
    m = np.diag(cap) - DT_S * a
    phi = np.linalg.solve(m, np.diag(cap))
    gamma = np.linalg.solve(m, DT_S * b)
    t_inf = np.linalg.solve(np.eye(3) - phi, gamma)
    t0 = np.array(initial_state())
    steps = round(DURATION_S / DT_S)
    lam, vec = np.linalg.eig(phi)
    coeff = np.linalg.solve(vec, t0 - t_inf)
    powers = lam[None, :] ** np.arange(1, steps + 1)[:, None]
    temps = t_inf[None, :] + (powers * coeff[None, :]) @ vec.T
    rows = np.empty((steps + 1, 5))
    rows[0] = [0.0, *t0, AIR_W_M2K * (t0[0] - AMBIENT_C)]
    rows[1:, 0] = np.arange(1, steps + 1) * DT_S
    rows[1:, 1:4] = temps.real
    rows[1:, 4] = g * (temps.real[:, 0] - AMBIENT_C)
    np.savetxt(out_path, rows, delimiter=",", fmt="%.17g", header="time_s,t1_c,t2_c,t3_c,heat_flux_w_m2", comments="")


def thermode_cmd(out_path):
    return [thermode_bin(), "simulate", "--material", "aluminium", "--model", "kron", "--dt", str(DT_S),
            "--duration", str(DURATION_S), "--out", out_path]


def peer_cmd(kind, out_path):
    return [sys.executable, os.path.abspath(__file__), "--run", kind, "--out", out_path]


def read_columns(path, names):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [[float(r[n]) for r in rows] for n in names]


def check_agreement(tmp):
    ours, theirs = os.path.join(tmp, "thermode.csv"), os.path.join(tmp, "peer.csv")
    subprocess.run(thermode_cmd(ours), check=True, capture_output=True)
    for kind in ("python", "numpy"):
        subprocess.run(peer_cmd(kind, theirs), check=True, capture_output=True)
        a = read_columns(ours, ["time_s", "epidermis_c", "dermis_c", "subcutis_c", "heat_flux_w_m2"])
        b = read_columns(theirs, ["time_s", "t1_c", "t2_c", "t3_c", "heat_flux_w_m2"])
        if len(a[0]) != len(b[0]):
            sys.exit(f"kron_numpy: {len(a[0])} thermode rows vs {len(b[0])} {kind} rows")
        temps = max(abs(x - y) for col in range(1, 4) for x, y in zip(a[col], b[col]))
        flux = max(abs(x - y) / max(1.0, abs(x)) for x, y in zip(a[4], b[4]))
        if temps > AGREE_C or flux > AGREE_C:
            sys.exit(f"kron_numpy: {kind} disagrees: temperatures {temps:.3e} °C, flux {flux:.3e} (relative)")
        print(f"kron_numpy: {kind} agrees with thermode: {temps:.2e} °C, flux {flux:.2e} relative", file=sys.stderr)


def main():
    parser = common.parser(__doc__)
    parser.add_argument("--run", choices=["python", "numpy"])
    parser.add_argument("--out")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    if args.run:
        material = aluminium()
        (run_python if args.run == "python" else run_numpy)(material, args.out)
        return
    with tempfile.TemporaryDirectory() as tmp:
        check_agreement(tmp)
        out = os.path.join(tmp, "timed.csv")
        for kind, label in (("python", "plain Python loop"), ("numpy", "vectorised NumPy")):
            pairs = [(common.timed(thermode_cmd(out)), common.timed(peer_cmd(kind, out))) for _ in range(args.repeats)]
            t_s = statistics.median(p[0] for p in pairs)
            p_s = statistics.median(p[1] for p in pairs)
            print(f"| kron aluminium 90 s at 1 ms with CSV vs {label} | {t_s:.3f} | {p_s:.3f} | {p_s / t_s:.1f} |")


if __name__ == "__main__":
    main()
