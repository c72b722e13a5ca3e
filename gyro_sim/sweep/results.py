"""Sweep results on disk: Parquet parts as batches finish, the table, the summary and the map.

    DIR/sweep.json                   what was run (resume checks it is the same sweep)
    DIR/parts/points-<i>-<j>.parquet one file per finished batch
    DIR/results.parquet              every row, by point index (written at the end)
    DIR/summary.md, DIR/map.png      the Markdown summary and the map

Every file is written under a temporary name and renamed when complete
(:func:`..io.safe_paths.atomic_output`): a crash or an interruption leaves each file whole or
absent, never half-written under its name (only a hidden ``.*.partial*`` file, which
:func:`clear` removes and :func:`read_parts` never reads).

Rows are plain dicts; the table's columns are, in order, those of the rows taken by point
index, so the table does not depend on how the points were batched or in which order the
batches finished.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from gyro_sim.safe_paths import PARTIAL, atomic_output, write_atomic

PARTS = "parts"
RESULTS = "results.parquet"
SUMMARY = "summary.md"
MAP = "map.png"
MANIFEST = "sweep.json"
OWNED = (RESULTS, SUMMARY, MAP, MANIFEST)


def part_name(points: list[int]) -> str:
    return f"points-{min(points):07d}-{max(points):07d}-{len(points)}.parquet"


def table_of(rows: list[dict[str, Any]]) -> pa.Table:
    """A table from rows, columns in order of first appearance (rows sorted by point); a row
    without a column gets null there."""
    rows = sorted(rows, key=lambda r: r["point"])
    cols: dict[str, None] = {}
    for r in rows:
        for k in r:
            cols.setdefault(k, None)
    return pa.Table.from_pydict({c: [r.get(c) for r in rows] for c in cols})


def write_part(out: Path, rows: list[dict[str, Any]]) -> Path:
    """One finished batch, atomically (a temporary name, then a rename): a crash leaves either
    the whole part or none of it (a batch run again replaces its part)."""
    d = out / PARTS
    d.mkdir(parents=True, exist_ok=True)
    with atomic_output(d / part_name([r["point"] for r in rows]), force=True, what="--out") as target:
        pq.write_table(table_of(rows), target.tmp)
    return target.path


def read_parts(out: Path) -> list[dict[str, Any]]:
    """Every row of DIR/parts (a point found twice, as after a retried batch, kept once)."""
    rows: dict[int, dict[str, Any]] = {}
    d = out / PARTS
    if not d.is_dir():
        return []
    for path in sorted(d.glob("points-*.parquet")):
        try:
            part = pq.read_table(path).to_pylist()
        except (OSError, pa.ArrowInvalid):
            continue  # a damaged part: its points are run again
        for r in part:
            # a column another part has but this one does not comes back as None: drop it
            rows.setdefault(int(r["point"]), {k: v for k, v in r.items() if v is not None or k == "error"})
    return list(rows.values())


def clear(out: Path) -> None:
    """Remove the files a sweep writes (for --force), and nothing else."""
    d = out / PARTS
    if d.is_dir():
        for p in d.glob("*.parquet"):
            p.unlink()
        for p in d.glob(".tmp-*"):
            p.unlink()
        for p in d.glob(f".points-*{PARTIAL}.parquet"):
            p.unlink()
    for name in OWNED:
        if (out / name).is_file():
            (out / name).unlink()
        stem, suffix = os.path.splitext(name)
        for p in out.glob(f".{stem}.*{PARTIAL}{suffix}"):
            p.unlink()


def write_manifest(out: Path, sweep) -> None:
    write_atomic(out / MANIFEST, json.dumps({"digest": sweep.digest(), "sweep": sweep.fingerprint(),
                                             "source": sweep.path}, indent=1, default=repr) + "\n",
                 force=True, what="--out")


def read_manifest(out: Path) -> dict[str, Any] | None:
    try:
        return json.loads((out / MANIFEST).read_text())
    except (OSError, ValueError):
        return None


# ------------------------------------------------------------------------------ summary
def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _scalar_measures(rows: list[dict]) -> list[str]:
    names = ("max_tilt_rad", "max_deviation_rad", "exact_error_rad", "max_drift", "cpu_s")
    return [n for n in names if any(n in r for r in rows)]


def summary(sweep, rows: list[dict], stats: dict[str, Any], check, largest_rows) -> str:
    """The Markdown summary."""
    n = len(sweep.points)
    lines = [f"# Sweep: {sweep.name}", ""]
    scene = sweep.scene_path or "inline mapping"
    run = sweep.run
    lines.append(f"- scene: `{scene}` ({sweep.scene.get('name', '')})")
    if sweep.kind == "grid":
        for k, vals in sweep.axes.items():
            num = [v for v in vals if isinstance(v, (int, float))]
            rng = f" from {min(num):.4g} to {max(num):.4g}" if len(num) == len(vals) and len(vals) > 1 else \
                f": {', '.join(map(_fmt, vals))}"
            lines.append(f"- grid `{k}`: {len(vals)} values{rng}")
    else:
        lines.append(f"- random: {sweep.draws} draws, seed {sweep.seed}")
        for k, (dist, args) in sweep.axes.items():
            lines.append(f"  - `{k}`: {dist} {args}")
    from gyro_sim.sweep.spec import simulates

    if not simulates(sweep.measures):
        lines.append("- run: none, a linearisation at each point's initial state")
    else:
        lines.append(f"- run: {run['integrator']}"
                     + (f" step {run['step']:g} s" if run["integrator"] in ("rk4", "lie4") else
                        f" rtol {run['rtol']:g}, atol {run['atol']:g}")
                     + f", horizon {run['horizon']:g} s in chunks of {run['chunk']:g} s, backend {run['backend']}")
    errors = [r for r in rows if not r["ok"]]
    lines.append(f"- points: {len(rows)} of {n}" + (" (--quick)" if sweep.quick else "")
                 + f"; simulation errors: {len(errors)}")
    if stats.get("wall"):
        lines.append(f"- wall time {stats['wall']:.1f} s for {stats['ran']} points run now "
                     f"({stats['ran'] / stats['wall']:.2f} points/s, {stats['where']})"
                     + (f"; {stats['skipped']} done before, skipped" if stats.get("skipped") else ""))
    lines.append("")
    if sweep.verdicts:
        lines += ["## Verdicts", "", "| verdict | rule | holds | fails |", "|---|---|---:|---:|"]
        for v in sweep.verdicts:
            yes = sum(1 for r in rows if r.get(f"verdict.{v['name']}"))
            lines.append(f"| {v['name']} | {v['measure']} < {v['below']:g} | {yes} | {len(rows) - yes} |")
        lines.append("")
    if check is not None:
        from gyro_sim.sweep.theory import FORMULA_TEXT

        ok = "yes" if check["within_one_cell"] else "NO"
        lines += ["## Against theory", "",
                  f"Formula `{check['formula']}`: {FORMULA_TEXT[check['formula']]} predicts `{check['verdict']}`.",
                  "",
                  f"- points agreeing with the formula: {check['agree']} of {check['points']}",
                  f"- disagreeing: {check['disagree']}, all within one grid cell of the formula's boundary: **{ok}**"
                  + (f" (farthest: {check['max_cells']:g} cells)" if check["disagree"] else ""), ""]
        if len(check["slices"]) > 1:
            lines += ["| slice | points | disagree | farthest (cells) |", "|---|---:|---:|---:|"]
            for s in check["slices"]:
                lines.append(f"| {', '.join(map(_fmt, s['group']))} | {s['points']} | {s['disagree']} | "
                             f"{s['max_cells']:g} |")
            lines.append("")
    if largest_rows:
        x, y = sweep.map["x"], sweep.map["y"]
        lines += [f"## Largest `{y}` with `{sweep.map['verdict']}` (every smaller grid value too)", ""]
        has_bound = any("theory_bound" in r for r in largest_rows)
        head = "| group | " + x + " | largest | first failing | theory (grid) |" + (" formula bound | largest / bound |"
                                                                                 if has_bound else "")
        lines += [head, "|---|---:|---:|---:|---:|" + ("---:|---:|" if has_bound else "")]
        for r in largest_rows:
            line = (f"| {', '.join(map(_fmt, r['group'])) or '-'} | {_fmt(r['x'])} | {_fmt(r['largest'])} | "
                    f"{_fmt(r['first_failing'])} | {_fmt(r.get('theory_largest'))} |")
            if has_bound:
                b = r.get("theory_bound")
                ratio = r["largest"] / b if (b and r["largest"]) else None
                line += f" {_fmt(b)} | {_fmt(ratio)} |"
            lines.append(line)
        lines.append("")
    meas = _scalar_measures(rows)
    if meas:
        lines += ["## Measures", "", "| measure | min | median | max |", "|---|---:|---:|---:|"]
        for m in meas:
            vals = sorted(float(r[m]) for r in rows if r.get(m) is not None and not math.isnan(float(r[m])))
            if vals:
                lines.append(f"| {m} | {vals[0]:.4g} | {vals[len(vals) // 2]:.4g} | {vals[-1]:.4g} |")
        lines.append("")
    if errors:
        lines += ["## Simulation errors (first 10)", ""]
        for r in errors[:10]:
            vals = ", ".join(f"{k} = {_fmt(r[k])}" for k in sweep.axes)
            lines.append(f"- point {r['point']} ({vals}): {r['error']}")
        lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- map
def plot(sweep, rows: list[dict], png: Path, largest_rows=None) -> None:
    """The PNG map: a heatmap of the verdict over a 2-D grid with the computed boundary and the
    formula's (one panel per slice of the other keys), the largest stable y against x, or
    histograms of the measures (random draws)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from gyro_sim.sweep.theory import slices

    kind = sweep.map["kind"]
    if kind == "histogram" or not rows:
        meas = _scalar_measures(rows) or ["t_reached"]
        fig, axs = plt.subplots(1, len(meas), figsize=(4.2 * len(meas), 3.4), squeeze=False)
        vname = sweep.map.get("verdict")
        for ax, m in zip(axs[0], meas):
            groups = [("all", rows)] if vname is None else [
                (f"{vname}", [r for r in rows if r.get(f"verdict.{vname}")]),
                (f"not {vname}", [r for r in rows if not r.get(f"verdict.{vname}")])]
            data = [[float(r[m]) for r in g if r.get(m) is not None and math.isfinite(float(r[m]))]
                    for _, g in groups]
            allv = [v for d in data for v in d]
            if allv:
                positive = min(allv) > 0 and max(allv) / max(min(allv), 1e-300) > 100
                bins = np.geomspace(min(allv), max(allv), 30) if positive else 30
                ax.hist(data, bins=bins, stacked=True, label=[g for g, _ in groups])
                if positive:
                    ax.set_xscale("log")
            ax.set_xlabel(m)
            ax.set_ylabel("points")
            if vname is not None:
                ax.legend(fontsize=7)
        fig.suptitle(f"{sweep.name} ({len(rows)} points)", fontsize=9)
        fig.tight_layout()
        fig.savefig(png, dpi=110)
        plt.close(fig)
        return
    x, y, vname = sweep.map["x"], sweep.map["y"], sweep.map["verdict"]
    xs, ys = sweep.axes[x], sweep.axes[y]

    def logscale(vals):
        return all(isinstance(v, (int, float)) and v > 0 for v in vals) and len(vals) > 2 and \
            max(vals) / min(vals) > 5 and abs((vals[2] - vals[1]) - (vals[1] - vals[0])) > 1e-9 * abs(vals[1])

    if kind == "largest":
        fig, ax = plt.subplots(figsize=(6.4, 4.4))
        groups: dict[tuple, list] = {}
        for r in largest_rows or []:
            groups.setdefault(r["group"], []).append(r)
        for gi, (g, items) in enumerate(groups.items()):
            label = ", ".join(map(str, g)) or "computed"
            color = f"C{gi}"
            pts = [(r["x"], r["largest"]) for r in items if r["largest"] is not None]
            if pts:  # groups often coincide: big hollow markers under small full ones
                ax.plot(*zip(*pts), "o-" if gi % 2 == 0 else "s:", color=color, ms=10 - 4 * (gi % 2),
                        mfc="none" if gi % 2 == 0 else color, label=f"{label}: largest {vname}")
            bad = [(r["x"], r["first_failing"]) for r in items if r["first_failing"] is not None]
            if bad:
                ax.plot(*zip(*bad), "x", color=color, alpha=0.6, label=f"{label}: first failing")
        bounds = sorted({(r["x"], r["theory_bound"]) for r in largest_rows or [] if r.get("theory_bound")})
        if bounds:
            ax.plot(*zip(*bounds), "k--", label="RK4 bound 2 sqrt(2) / w_n")
        ax.set_xscale("log" if logscale(xs) else "linear")
        ax.set_yscale("log" if logscale(ys) else "linear")
        ax.set_xlabel(x)
        ax.set_ylabel(f"largest {y}")
        ax.legend(fontsize=7)
        ax.set_title(sweep.name, fontsize=9)
        fig.tight_layout()
        fig.savefig(png, dpi=110)
        plt.close(fig)
        return
    sl = slices(sweep, rows)
    fig, axs = plt.subplots(1, len(sl), figsize=(5.6 * len(sl), 4.6), squeeze=False)
    from matplotlib.colors import ListedColormap

    for ax, (g, cells) in zip(axs[0], sl.items()):
        V = np.full((len(ys), len(xs)), np.nan)
        T = np.full((len(ys), len(xs)), np.nan)
        for (i, j), r in cells.items():
            V[j, i] = 1.0 if r.get(f"verdict.{vname}") else 0.0
            if r.get("theory_margin") is not None:
                T[j, i] = math.log(max(float(r["theory_margin"]), 1e-300))
        xv = np.array(xs, dtype=float)
        yv = np.array(ys, dtype=float)
        ax.pcolormesh(xv, yv, V, shading="nearest", cmap=ListedColormap(["#e8a2a2", "#a6d8a6"]), vmin=0, vmax=1)
        if np.nanmin(V) < 0.5 < np.nanmax(V):
            ax.contour(xv, yv, V, levels=[0.5], colors="k", linewidths=1.6)
            ax.plot([], [], "k-", label=f"computed boundary of {vname}")
        if np.isfinite(T).any() and np.nanmin(T) < 0 < np.nanmax(T):
            ax.contour(xv, yv, T, levels=[0.0], colors="b", linestyles="--", linewidths=1.4)
            ax.plot([], [], "b--", label=f"theory ({sweep.theory['formula']})")
        ax.set_xscale("log" if logscale(xs) else "linear")
        ax.set_yscale("log" if logscale(ys) else "linear")
        ax.set_xlabel(x)
        ax.set_ylabel(y)
        ax.set_title((", ".join(map(str, g)) + ": " if g else "") + f"green: {vname}, red: not", fontsize=8)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle(sweep.name, fontsize=9)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def finish(sweep, out: Path, rows: list[dict], stats: dict[str, Any]) -> dict[str, Any]:
    """results.parquet, summary.md and map.png from every row; returns the theory check."""
    from gyro_sim.sweep.theory import boundary_check, largest

    table = table_of(rows)
    with atomic_output(out / RESULTS, force=True, what="--out") as target:
        pq.write_table(table, target.tmp)
    check = boundary_check(sweep, rows) if len(rows) == len(sweep.points) else None
    big = largest(sweep, rows) if sweep.map["kind"] == "largest" else None
    text = summary(sweep, rows, stats, check, big)
    write_atomic(out / SUMMARY, text + "\n", force=True, what="--out")
    with atomic_output(out / MAP, force=True, what="--out") as target:
        plot(sweep, rows, target.tmp, big)
    return {"check": check, "largest": big, "summary": text}


