"""Drive AUTO-07p on jaxrod's discrete strip (see strip.f90): build, write data, run, parse.

No AUTO Python interface is used: the equation file is compiled once with gfortran and
linked against AUTO-07p's object files (what AUTO's own `cmds.make` does), and each
continuation is one run of that executable in a scratch directory holding

* `fort.2`   -- the constants (AUTO-07p's keyword format),
* `mesh.dat` -- N, G, the segment lengths h_i, hinge lengths ell_k, natural turning angles,
* `start.dat` -- the starting state (theta, mu) at alpha = 0, computed by jaxrod.

AUTO writes the bifurcation diagram to `fort.7`; `parse_fort7` reads the special points
(TY 1 = BP, 2 = LP for algebraic problems; 9 = EP end point, -9 = MX no convergence).

Install: `apt-get install auto-07p gfortran` (Debian/Ubuntu). AUTO_DIR defaults to
/usr/lib/auto-07p. Set OMP_NUM_THREADS=1: the Debian build uses OpenMP, which is far slower
on a 2-core machine.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np


HERE = Path(__file__).resolve().parent
EQUATION = HERE / "strip.f90"
TY_NAMES = {1: "BP", 2: "LP", 3: "HB", 4: "RG", -4: "UZ", 9: "EP", -9: "MX"}


def auto_dir():
    return Path(os.environ.get("AUTO_DIR", "/usr/lib/auto-07p"))


def available():
    """(ok, reason): AUTO-07p's library objects and gfortran are both present."""
    libs = sorted((auto_dir() / "lib").glob("*.o"))
    if not libs:
        return False, f"AUTO-07p not installed (no object files in {auto_dir() / 'lib'}; apt-get install auto-07p)"
    if shutil.which("gfortran") is None:
        return False, "gfortran not found (apt-get install gfortran), needed to compile the AUTO equation file"
    return True, ""


def build(workdir):
    """Compile strip.f90 and link it with AUTO-07p: returns the executable's path and
    the build time (s)."""
    ok, why = available()
    if not ok:
        raise RuntimeError(why)
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    exe = workdir / "strip.exe"
    libs = [str(p) for p in sorted((auto_dir() / "lib").glob("*.o"))]
    t0 = time.perf_counter()
    flags = ["-O2", "-fPIC", "-std=legacy", "-fopenmp"]
    subprocess.run(["gfortran", *flags, "-c", str(EQUATION), "-o", str(workdir / "strip.o"),
                    "-J", str(workdir)], check=True, capture_output=True, text=True)
    subprocess.run(["gfortran", *flags, str(workdir / "strip.o"), *libs, "-o", str(exe)],
                   check=True, capture_output=True, text=True)
    return exe, time.perf_counter() - t0


def write_mesh(path, d, gap, scaling=0):
    """mesh.dat from a `jaxrod.discretize(scene)` result; `scaling=1` multiplies the angle
    equations by h_i (see strip.f90)."""
    h, ell, phi0 = (np.asarray(x, np.float64) for x in (d.h, d.ell, d.phi0))
    with open(path, "w") as f:
        f.write(f"{h.size} {float(gap)!r} {int(scaling)}\n")
        f.writelines(f"{float(x)!r}\n" for x in h)
        f.writelines(f"{float(a)!r} {float(b)!r}\n" for a, b in zip(ell, phi0))


def write_start(path, theta, mu):
    with open(path, "w") as f:
        f.writelines(f"{float(x)!r}\n" for x in np.concatenate([np.asarray(theta), np.asarray(mu)]))


# Tolerances: "tight" matches jaxrod's refinement (alpha_c to ~1e-8 deg); "default" is
# AUTO-07p's usual demo setting (EPSL = EPSU = 1e-7, EPSS = 1e-5) with a larger step.
TOLERANCES = {
    "tight": dict(EPSL=1e-10, EPSU=1e-10, EPSS=1e-10, DS=0.02, DSMIN=1e-8, DSMAX=0.1, ITMX=20),
    "default": dict(EPSL=1e-7, EPSU=1e-7, EPSS=1e-5, DS=0.02, DSMIN=1e-5, DSMAX=0.5, ITMX=8),
}


def constants(n, direction, *, EPSL, EPSU, EPSS, DS, DSMIN, DSMAX, ITMX, NMX=2000, ISP=2,
              stop_first=True, bound=np.pi):
    """AUTO-07p constants: algebraic problem (IPS=0), start from STPNT (IRS=0), parameter
    PAR(1) = alpha, detect folds (ILP=1) and branch points (ISP=2), stop at the first one."""
    stop = "STOP=['LP1','BP1']\n" if stop_first else ""
    return (
        f"NDIM={n + 2}, IPS=0, IRS=0, ILP=1\n"
        "ICP=[1]\n"
        f"NTST=1, NCOL=1, IAD=0, ISP={ISP}, ISW=1, IPLT=0, NBC=0, NINT=0\n"
        f"NMX={NMX}, NPR=100000, MXBF=0, IID=0, ITMX={ITMX}, ITNW=10, NWTN=3, JAC=1\n"
        f"EPSL={EPSL:.3e}, EPSU={EPSU:.3e}, EPSS={EPSS:.3e}\n"
        f"DS={direction * DS:.6e}, DSMIN={DSMIN:.3e}, DSMAX={DSMAX:.6e}, IADS=1\n"
        "NPAR=2, THL={}, THU={}\n"
        f"UZSTOP={{1: [{-bound:.6f}, {bound:.6f}]}}\n"
        + stop
    )


def parse_fort7(path):
    """Rows of fort.7 as dicts: branch, point, type (int), label, alpha (PAR(1)), l2norm."""
    rows = []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if len(parts) < 6 or parts[0] == "0":
                continue
            try:
                br, pt, ty, lab = (int(x) for x in parts[:4])
                vals = [float(x) for x in parts[4:]]
            except ValueError:
                continue
            rows.append(dict(branch=br, point=pt, type=ty, label=lab, alpha=vals[0], l2norm=vals[1]))
    return rows


def run(exe, rundir, d, gap, theta0, mu0, direction, tolerances="tight", scaling=0, timeout=None, **kw):
    """One continuation from (theta0, mu0) at alpha = 0 in the given direction (+1 snap
    up, -1 snap down). Returns dict(wall_s, first special point, all special points, rows).
    Raises subprocess.TimeoutExpired after `timeout` seconds."""
    rundir = Path(rundir)
    rundir.mkdir(parents=True, exist_ok=True)
    for name in ("fort.7", "fort.8", "fort.9"):
        (rundir / name).unlink(missing_ok=True)
    write_mesh(rundir / "mesh.dat", d, gap, scaling)
    write_start(rundir / "start.dat", theta0, mu0)
    tol = dict(TOLERANCES[tolerances]) if isinstance(tolerances, str) else dict(tolerances)
    tol.update(kw)
    (rundir / "fort.2").write_text(constants(len(theta0), direction, **tol))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    t0 = time.perf_counter()
    p = subprocess.run([str(exe)], cwd=rundir, env=env, capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t0
    if p.returncode != 0 or not (rundir / "fort.7").exists():
        raise RuntimeError(f"AUTO run failed (rc={p.returncode}): {p.stdout[-500:]} {p.stderr[-500:]}")
    rows = parse_fort7(rundir / "fort.7")
    special = [r for r in rows if r["type"] in (1, 2)]
    first = special[0] if special else None
    return dict(wall_s=wall, first=first, special=special, rows=rows,
                points=max((abs(r["point"]) for r in rows), default=0), stdout=p.stdout)
