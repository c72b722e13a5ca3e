"""Writing a report's files: Markdown, JSON and the PNG plot (each `gyro-sim bench` command).

No silent overwrite: existing report files are refused unless ``--force``, checked before the
benchmark starts (:func:`refused`, which also creates --out, so that a directory that cannot be
made is said before the work) and again when each file is published. Each file is written under
a temporary name and renamed when complete (:func:`..io.safe_paths.atomic_output`).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Callable

from gyro_sim.safe_paths import AtomicOutput, OutputError, check_output, write_atomic

#: the files of a report <name>: <out>/<name>.<suffix>
SUFFIXES = ("md", "json", "png")


def add_force_option(parser) -> None:
    """`--force` on a bench command's parser."""
    parser.add_argument("--force", action="store_true", help="replace existing report files in --out")


def check_report(out: str | Path, name: str, force: bool = False) -> list[Path]:
    """The paths <out>/<name>.md, .json, .png, checked (OutputError if one exists and not
    `force`, if --out is a file, or if a path is a directory)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out: {out}: is a file, not a directory")
    paths = [out / f"{name}.{suffix}" for suffix in SUFFIXES]
    if out.is_dir():
        for path in paths:
            check_output(path, force=force, what="--out")
    return paths


def _make_dir(out: str | Path) -> None:
    try:
        Path(out).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"--out: {out}: cannot make the directory ({exc.strerror or exc})") from None


def refused(args, name: str) -> bool:
    """Check the report's outputs before a bench runs: print one line and return True if refused."""
    try:
        check_report(args.out, name, getattr(args, "force", False))
        _make_dir(args.out)
        check_report(args.out, name, getattr(args, "force", False))
    except OutputError as exc:
        print(f"gyro-sim bench {name}: {exc}", file=sys.stderr)
        return True
    return False


def write_report(out: str | Path, name: str, markdown: str, data: Any, plot: Callable[[str], None], *,
                 force: bool = False, json_default: Callable = float) -> list[Path]:
    """Write <out>/<name>.md, .json and .png (the plot is skipped without matplotlib); print
    and return the paths written. Existing files are refused (OutputError) unless `force`."""
    md, js, png = check_report(out, name, force)
    _make_dir(out)
    write_atomic(md, markdown, force=force, what="--out")
    write_atomic(js, json.dumps(data, indent=1, default=json_default), force=force, what="--out")
    written = [md, js]
    target = AtomicOutput(png, force=force, what="--out")
    try:
        plot(str(target.tmp))
        if target.tmp.stat().st_size:  # a plot with nothing to draw writes nothing
            written.append(target.publish())
    except ImportError:
        print("(install matplotlib for the plot)")
    finally:
        target.discard()
    print("\nwrote " + ", ".join(str(w) for w in written))
    return written
