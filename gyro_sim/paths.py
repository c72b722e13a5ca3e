"""Finding the package's own files (config/ scenes) in every install layout.

`pip install -e .` skips data_files (ROS 2 from PyPI does not install them in develop mode), so the source tree is tried
first, then the data_files location under sys.prefix, then the ament index.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path


def config_dirs() -> list[Path]:
    dirs = [Path(__file__).resolve().parents[1] / "config", Path(sys.prefix) / "share" / "gyro_sim" / "config"]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / "gyro_sim" / "config")
    return [d for d in dirs if d.is_dir()]


#: files in config/ that are not scenes (ROS parameter files for the node)
NOT_SCENES = ("params.yaml",)
#: files of config/models/ that are no models (the ROS package that names the shipped meshes)
NOT_MODELS = ("package.xml",)
#: suffixes of MJCF and URDF models (read through MuJoCo: gyro_sim.scene.mjcf)
MODEL_SUFFIXES = (".xml", ".mjcf", ".urdf")
#: where the shipped models are, under config/
MODELS_DIR = "models"


def shipped_scenes() -> list[Path]:
    """The scene files of the first config/ directory found (the source tree when present)."""
    dirs = config_dirs()
    return [] if not dirs else sorted(p for p in dirs[0].glob("*.yaml") if p.name not in NOT_SCENES)


def shipped_models() -> list[Path]:
    """The MJCF and URDF models of config/models/ (the source tree when present)."""
    dirs = config_dirs()
    return [] if not dirs else sorted(p for p in (dirs[0] / MODELS_DIR).glob("*")
                                      if p.suffix.lower() in MODEL_SUFFIXES and p.name not in NOT_MODELS)


def find_scene(name: str | os.PathLike) -> Path:
    """A scene file by path, or a shipped scene by its bare name (`double_gyro_plus` or
    `double_gyro_plus.yaml`, from config/ of the source tree or the install, wherever the
    user stands; a shipped model by its file name, `arm_flywheel.xml`, from config/models/).
    A name with a directory part (`/no/such/dir/chain_4.yaml`, `./chain_4.yaml`) is a path
    and only a path: FileNotFoundError ("no such file") if it is not a file there."""
    text = os.fspath(name)
    p = Path(text).expanduser()
    if p.is_file():
        return p
    if p.exists():
        raise FileNotFoundError(f"scene {text!r}: not a file")
    if not text.strip() or Path(text).name != text:
        raise FileNotFoundError(f"scene {text!r}: no such file")
    if p.suffix.lower() in MODEL_SUFFIXES:  # a shipped model by its file name
        for d in config_dirs():
            if (d / MODELS_DIR / p.name).is_file() and p.name not in NOT_MODELS:
                return d / MODELS_DIR / p.name
        known = sorted({f.name for f in shipped_models()})
        raise FileNotFoundError(f"model {text!r} not found (shipped models: {', '.join(known) or 'none'})")
    stem = p.name if p.suffix in (".yaml", ".yml") else p.name + ".yaml"
    for d in config_dirs():
        if (d / stem).is_file() and stem not in NOT_SCENES:
            return d / stem
    known = sorted({f.stem for d in config_dirs() for f in d.glob("*.yaml") if f.name not in NOT_SCENES})
    raise FileNotFoundError(f"scene {text!r} not found (shipped scenes: {', '.join(known) or 'none'})")
