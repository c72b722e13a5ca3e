"""Files of the gyro_sim package named by their path inside it (the compiled loops' cache keys)."""
from __future__ import annotations

from pathlib import Path

import gyro_sim

PACKAGE_DIR = Path(gyro_sim.__file__).resolve().parent


def in_package(path) -> str:
    """A file's path inside the gyro_sim package, with forward slashes."""
    return Path(path).resolve().relative_to(PACKAGE_DIR).as_posix()
