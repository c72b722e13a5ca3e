"""`gyro-sim import`: an MJCF or URDF model written as a gyro_sim scene (YAML).

Registered by :func:`register` (see ``gyro_sim.cli.PLUGINS``); MuJoCo is imported when the
command runs. The mapping is :mod:`gyro_sim.scene.mjcf` (docs/models.md).
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

EXAMPLES = """examples:
  gyro-sim import arm_flywheel.xml -o arm_flywheel.yaml
  gyro-sim import satellite_wheels.xml -o satellite.yaml --keyframe tumble --force

MODEL is an MJCF (.xml, .mjcf) or URDF (.urdf) file, or a shipped model of config/models/ by
its file name. The scene written loads and moves as the model does in MuJoCo (contacts aside);
its header comment says how MuJoCo's controls map onto the axis moments."""


def _err(msg) -> None:
    print(f"gyro-sim import: {msg}", file=sys.stderr)


def _write_new(path: Path, text: str, force: bool) -> None:
    """Write `text` to `path` through a temporary file in the same directory: the file appears
    whole or not at all, and without `force` an existing file (even one that appeared since the
    check) is never replaced (FileExistsError)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.resolve().parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as stream:
            stream.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # as a file opened for writing (mkstemp makes it 0600)
        if force:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)  # fails if path exists
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)


def add_model_options(parser) -> None:
    """The options of a command that reads a model (`run`, `import`): where its packages are."""
    parser.add_argument("--package-path", action="append", default=[], metavar="DIR",
                        help="models only: a directory searched first for the packages of "
                             "package:// URIs (repeatable; then the ament index, ROS_PACKAGE_PATH, "
                             "the package.xml above the file: docs/models.md)")
    parser.add_argument("--lock", action="append", default=[], metavar="JOINT[=VALUE]",
                        help="models only: weld JOINT at VALUE (rad or m; default its keyframe or "
                             "reference position), its body merged into its parent (repeatable: a "
                             "gripper's fingers, a target's slides)")
    parser.add_argument("--balance-inertia", action="store_true",
                        help="models only: a moving body's inertia outside the triangle inequality "
                             "A + B >= C takes MuJoCo's balanced one (its principal moments set to "
                             "their mean) instead of being refused (docs/models.md)")
    parser.add_argument("--geared-motors", type=float, default=None, metavar="GEAR",
                        help="models only: every hinge's armature a becomes the geared motor it "
                             "reflects, a rotor of inertia a / GEAR^2 on the parent turning GEAR "
                             "times the joint's rate (docs/models.md)")


def model_options(args) -> dict:
    """`load_scene`'s and `import_model`'s keyword arguments from a command's options."""
    return {"keyframe": getattr(args, "keyframe", None),
            "package_path": list(getattr(args, "package_path", None) or []),
            "lock": list(getattr(args, "lock", None) or []),
            "balance_inertia": bool(getattr(args, "balance_inertia", False)),
            "geared_motors": getattr(args, "geared_motors", None)}


def node_model_options(values: dict) -> dict:
    """`load_scene`'s model arguments from the node's parameters `lock` (comma-separated
    JOINT[=VALUE]) and `package_path` (directories separated by os.pathsep)."""
    lock = [item.strip() for item in str(values.get("lock") or "").split(",") if item.strip()]
    paths = [item for item in str(values.get("package_path") or "").split(os.pathsep) if item.strip()]
    return {"lock": lock, "package_path": paths}


def cmd_import(args) -> int:
    from gyro_sim.paths import find_scene
    from gyro_sim.safe_paths import OutputError, check_output
    from gyro_sim.scene.load import SceneError, load_scene, parse_yaml
    from gyro_sim.scene.mjcf import ModelError, import_model, is_model_path, scene_yaml

    try:
        model = find_scene(args.model)
    except FileNotFoundError as exc:
        _err(exc)
        return 2
    if not is_model_path(model):
        _err(f"{args.model}: not an MJCF or URDF model (.xml, .mjcf or .urdf); a YAML scene "
             "needs no import")
        return 2
    try:
        out = check_output(args.output, inputs=[model], force=args.force, what="-o")
    except OutputError as exc:
        _err(exc)
        return 2
    try:
        imported = import_model(model, **model_options(args))
    except ModelError as exc:
        for line in exc.errors:
            _err(line)
        return 2
    try:
        scene = load_scene(imported.mapping)
    except SceneError as exc:
        for line in imported.describe(exc.errors):
            _err(line)
        return 2
    text = scene_yaml(imported)
    if parse_yaml(text, str(out)) != imported.mapping:  # a guard: the YAML must read back exactly
        _err(f"{out}: the YAML written would not read back as the scene; nothing written")
        return 1
    try:
        _write_new(out, text, args.force)
    except FileExistsError:
        _err(f"-o: {out}: exists; refused to overwrite it (use --force)")
        return 2
    except OSError as exc:
        _err(f"-o: {out}: cannot write ({exc.strerror or exc})")
        return 1
    rotors = sum(len(b.rotors) for b in scene.bodies)
    axes = [name for b in scene.bodies  # in command order (docs/scene-format.md)
            for name in ([b.name] if b.joint.type in ("hinge", "slide") else [])
            + [r.name for r in b.rotors if r.actuated]]
    imus = f", IMUs {[imu.name for imu in scene.imus]}" if scene.imus else ""
    print(f"wrote {out}: scene '{scene.name}', {len(scene.bodies)} bodies, {rotors} rotors, "
          f"{scene.base.type} base, commanded axes {axes}{imus}")
    for note in imported.notes:
        print(f"  note: {note}")
    return 0


def register(sub, bench) -> None:
    """Add `import` to the `gyro-sim` subparsers."""
    from argparse import RawDescriptionHelpFormatter

    p = sub.add_parser("import", help="write an MJCF or URDF model (MuJoCo) as a gyro_sim scene",
                       description="Write an MJCF or URDF model as a gyro_sim scene file (YAML): "
                                   "its bodies (a chain or a tree), rotors, gravity, IMUs and the initial state "
                                   "of a keyframe. docs/models.md gives the mapping.",
                       epilog=EXAMPLES, formatter_class=RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL", help="the MJCF or URDF file")
    p.add_argument("-o", "--output", required=True, metavar="SCENE.yaml", help="the scene file to write")
    p.add_argument("--keyframe", metavar="NAME",
                   help="the keyframe giving the initial state and the servos' controls (default: the first; "
                        "none: rest)")
    p.add_argument("--force", action="store_true", help="replace an existing output file (never the model)")
    add_model_options(p)
    p.set_defaults(fn=cmd_import)
