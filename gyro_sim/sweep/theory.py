"""Stability formulas the shipped sweeps are checked against, and the "within one grid cell" test.

Each formula takes a point's loaded scene and run options and returns a margin: the verdict is
predicted to hold where the margin is > 1. The quantities are read from the scene itself
(body 1, its rotors included), so a sweep may vary any of them.

- ``kapitza``: an inverted pendulum on a base vibrating along the vertical with amplitude a and
  angular frequency W = 2 pi f stays up when (a W)^2 > 2 g I / (m c) (Kapitza 1951; I about
  the suspension point, c from it to the centre of mass). Margin (a W)^2 m c / (2 g I).
- ``maievski``: a heavy top spinning upright ("sleeping") is stable when its axial angular
  momentum H = A p satisfies H^2 > 4 B m g c (Maievski's criterion; B transverse about the
  support point O). With rotors, H = A_0 w_z + sum A_i p_i. Margin H^2 / (4 B m g c).
- ``explicit_rk4``: classical RK4 is stable on an oscillation of angular frequency w when
  h w <= 2 sqrt(2) (its stability region meets the imaginary axis at +-2.83 i). For a fast
  gyrostat the fastest mode is the nutation, w_n = H / B. Margin 2 sqrt(2) / (h w_n).
"""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import numpy as np

#: where RK4's stability region crosses the imaginary axis: |R(iy)| = 1 at y = 2 sqrt(2)
RK4_IMAGINARY_LIMIT = 2.0 * math.sqrt(2.0)


def _body_terms(scene) -> dict[str, float]:
    """Mass, |c|, axial and transverse inertia about O^1 (body z-axis), spin and axial angular
    momentum of the first body with its rotors; gravity g."""
    b = scene.bodies[0]
    m = float(b.mass)
    mc = b.mass * np.asarray(b.com, dtype=float)
    A = float(b.inertia[2, 2])
    B = float(b.inertia[0, 0])
    ini = b.initial
    if ini.angular_velocity is not None:
        wz = float(ini.angular_velocity[2])
    else:
        th = float(ini.euler[1])
        wz = float(ini.euler_rates[0] * math.cos(th) + ini.euler_rates[2])
    H = A * wz
    for r in b.rotors:
        h = np.asarray(r.position, dtype=float)
        m += r.mass
        mc = mc + r.mass * h
        B += r.transverse_inertia + r.mass * (h[1] ** 2 + h[2] ** 2)  # about the body x-axis (rotor along z)
        A_axis = r.axial_inertia * abs(float(np.asarray(r.axis) @ np.array([0.0, 0.0, 1.0])))
        A += A_axis
        # torque rotor: absolute spin p_i; speed rotor: kappa' relative to the carrier
        H += r.axial_inertia * (r.spin if r.mode == "torque" else r.spin + wz)
    g = 0.0 if scene.gravity is None else float(np.linalg.norm(scene.gravity))
    return {"m": m, "c": float(np.linalg.norm(mc)) / m, "A": A, "B": B, "H": H, "g": g}


def kapitza(scene, run: Mapping[str, Any]) -> float:
    t = _body_terms(scene)
    if scene.base.type != "moving":
        return 0.0
    a = float(np.linalg.norm(scene.base.amplitude))
    W = 2.0 * math.pi * float(scene.base.frequency)
    return (a * W) ** 2 * t["m"] * t["c"] / (2.0 * t["g"] * t["B"])


def maievski(scene, run: Mapping[str, Any]) -> float:
    t = _body_terms(scene)
    return t["H"] ** 2 / (4.0 * t["B"] * t["m"] * t["g"] * t["c"])


def explicit_rk4(scene, run: Mapping[str, Any]) -> float:
    t = _body_terms(scene)
    w_n = abs(t["H"]) / t["B"]
    return RK4_IMAGINARY_LIMIT / (float(run["step"]) * w_n) if w_n > 0 else math.inf


FORMULAS: dict[str, Callable[[Any, Mapping[str, Any]], float]] = {
    "kapitza": kapitza, "maievski": maievski, "explicit_rk4": explicit_rk4,
}
#: how each formula reads, for the summary
FORMULA_TEXT = {
    "kapitza": "(a W)^2 > 2 g I / (m c)",
    "maievski": "(A p)^2 > 4 B m g c",
    "explicit_rk4": "h w_n < 2 sqrt(2), w_n = H / B (RK4 on the nutation)",
}


# ------------------------------------------------------------------------- grid geometry
def grid_index(sweep, rows: list[dict]) -> dict[str, dict[Any, int]]:
    """For each grid key, value -> its index along the axis."""
    return {k: {v: i for i, v in enumerate(vals)} for k, vals in sweep.axes.items()}


def slices(sweep, rows: list[dict]) -> dict[tuple, dict[tuple[int, int], dict]]:
    """Rows of a grid sweep grouped by the keys other than map x and y: group values ->
    {(i_x, i_y): row}."""
    idx = grid_index(sweep, rows)
    x, y = sweep.map["x"], sweep.map["y"]
    others = [k for k in sweep.axes if k not in (x, y)]
    out: dict[tuple, dict[tuple[int, int], dict]] = {}
    for r in rows:
        g = tuple(r[k] for k in others)
        out.setdefault(g, {})[(idx[x][r[x]], idx[y][r[y]])] = r
    return out


def boundary_check(sweep, rows: list[dict]) -> dict[str, Any] | None:
    """Compare the computed verdict with the theory's on a grid, in each slice of the map's x
    and y. A point where they differ is "within one cell" when a neighbouring grid point (one
    step along x, y or both) is predicted on the other side of the formula's boundary: the
    computed boundary then passes within one grid cell of the formula's.

    Returns {"points", "agree", "disagree", "max_cells", "within_one_cell", "slices": [...]}
    (max_cells: the largest Chebyshev distance, in grid cells, from a disagreeing point to the
    nearest point predicted on the other side), or None without a theory or a 2-D grid map."""
    th = sweep.theory
    if th is None or sweep.kind != "grid" or sweep.map.get("x") is None:
        return None
    verdict = th["verdict"]
    col_v, col_t = f"verdict.{verdict}", f"theory.{verdict}"
    per_slice = []
    total = agree = 0
    worst = 0.0
    for group, cells in slices(sweep, rows).items():
        pred = {k: bool(r[col_t]) for k, r in cells.items()}
        bad = []
        for (i, j), r in cells.items():
            total += 1
            if bool(r[col_v]) == pred[(i, j)]:
                agree += 1
                continue
            dist = min((max(abs(i - a), abs(j - b)) for (a, b), p in pred.items() if p != pred[(i, j)]),
                       default=math.inf)
            bad.append(((i, j), dist))
            worst = max(worst, dist)
        per_slice.append({"group": group, "points": len(cells), "disagree": len(bad),
                          "max_cells": max((d for _, d in bad), default=0.0)})
    return {"verdict": verdict, "formula": th["formula"], "points": total, "agree": agree,
            "disagree": total - agree, "max_cells": worst, "within_one_cell": worst <= 1, "slices": per_slice}


def largest(sweep, rows: list[dict]) -> list[dict[str, Any]]:
    """For a "largest" map: in each slice and at each x, the largest y whose verdict holds at it
    and at every smaller y on the grid (e.g. the largest stable step), the first y where it
    fails, and the same read from the theory's prediction (and, for explicit_rk4, the formula's
    exact bound)."""
    x, y = sweep.map["x"], sweep.map["y"]
    vname = sweep.map["verdict"]
    ys = sorted(sweep.axes[y])
    out = []
    for group, cells in slices(sweep, rows).items():
        by_x: dict[Any, dict[Any, dict]] = {}
        for r in cells.values():
            by_x.setdefault(r[x], {})[r[y]] = r
        for xv in sorted(by_x):
            col = by_x[xv]
            best = first_bad = None
            for yv in ys:
                if yv not in col:
                    break
                if col[yv][f"verdict.{vname}"]:
                    best = yv
                else:
                    first_bad = yv
                    break
            item = {"group": group, "x": xv, "largest": best, "first_failing": first_bad}
            if sweep.theory is not None and f"theory.{vname}" in next(iter(col.values())):
                tb = None
                for yv in ys:
                    if yv in col and col[yv][f"theory.{vname}"]:
                        tb = yv
                    else:
                        break
                item["theory_largest"] = tb
                r0 = col[ys[0]] if ys[0] in col else next(iter(col.values()))
                if sweep.theory["formula"] == "explicit_rk4":
                    item["theory_bound"] = r0[y] * r0["theory_margin"]
            out.append(item)
    return out
