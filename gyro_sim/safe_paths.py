"""Output paths checked before anything runs: no silent overwrite (SPEC.md, "Contracts").

Every file the package writes goes through :func:`check_output` first::

    check_output("run.mcap", inputs=[scene_path], force=args.force)

It refuses, each with one line naming the path:

- an output that already exists, unless ``force=True`` (CLI ``--force``, node ``overwrite:=true``);
- an output that *is* one of the inputs, by identity (``os.path.samefile``: the same file
  through a hard link or a symlink counts, a mere equal name is not needed), even with force;
- a directory, an output whose directory is missing, or a directory that is not writable.

No ROS and no third-party imports here: the node's parameter validation uses it too.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

from gyro_sim.errors import GyroSimError

__all__ = ["OutputError", "check_output", "check_outputs"]


class OutputError(GyroSimError, ValueError):
    """An output path is refused (bad input: console scripts exit with status 2)."""


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (or cannot be stat'ed): not the same file
        return False


def check_output(path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike | None] = (),
                 force: bool = False, what: str = "output") -> Path:
    """The output `path`, checked (module docstring); raise OutputError otherwise.

    Parameters
    ----------
    path : the file about to be written
    inputs : files the command reads (None entries ignored); the output may never be one of them
    force : allow replacing an existing regular file that is not an input
    what : how the message names the path ("output", "--record", "record", ...)
    """
    if path is None or not str(path).strip():
        raise OutputError(f"{what}: empty path")
    p = Path(path).expanduser()
    for src in inputs:
        if src is not None and str(src) and _same(p, Path(src).expanduser()):
            raise OutputError(f"{what}: {p}: is the input {src} (the same file): refused, "
                              "it would destroy the input; give another path")
    if p.is_dir():
        raise OutputError(f"{what}: {p}: is a directory; give a file path")
    if os.path.lexists(p):
        if not p.exists():  # a dangling symlink: writing would create its target somewhere else
            raise OutputError(f"{what}: {p}: is a broken symbolic link; refused")
        if not p.is_file():
            raise OutputError(f"{what}: {p}: exists and is not a regular file; refused")
        if not force:
            raise OutputError(f"{what}: {p}: exists; refused to overwrite it (use --force, or "
                              "overwrite:=true for the node)")
        if not os.access(p, os.W_OK):
            raise OutputError(f"{what}: {p}: exists and is not writable")
    parent = p.resolve().parent
    if not parent.is_dir():
        raise OutputError(f"{what}: directory {parent} does not exist (for {p.name})")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{what}: directory {parent} is not writable (for {p.name})")
    return p


def check_outputs(paths: Iterable[str | os.PathLike], **kw) -> list[Path]:
    """:func:`check_output` on each path (all checked before any is written)."""
    return [check_output(p, **kw) for p in paths]
