"""The node's parameters: names, types, defaults, documentation and validation (no rclpy here).

`PARAMETERS` is the single table the node declares from (with descriptors) and `validate`
turns the values it got into a `NodeConfig`, or raises `ParameterError` naming every
parameter that is wrong and why, before anything is created or published.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from gyro_sim.errors import GyroSimError

#: largest physics rate accepted (Hz): beyond it one step is shorter than a Python call
MAX_PHYSICS_RATE = 100_000.0
#: relative tolerance on physics_rate / publish_rate being a whole number of steps
RATIO_TOLERANCE = 1e-9
#: the values of `hold`: none (run from the start), until_command (the initial state held until
#: the first command)
HOLDS = ("none", "until_command")
#: default of record_queue_mb (MB waiting for the log writer before publications are dropped)
RECORD_QUEUE_MB = 64.0


class ParameterError(GyroSimError, ValueError):
    """One or more parameters are invalid; the message lists them all, one per line."""


@dataclass(frozen=True)
class Parameter:
    name: str
    kind: type  # float, str or bool
    default: object
    description: str
    low: float | None = None  # inclusive bounds of numbers (descriptor ranges)
    high: float | None = None


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("scene", str, "hinge_chain", "scene file (YAML), or the name of a shipped scene in config/"),
    Parameter("lock", str, "", "models only: joints welded where they are, comma-separated JOINT or JOINT=VALUE "
              "(rad or m; default the keyframe's or reference position), as gyro-sim run --lock"),
    Parameter("package_path", str, "", "models only: directories searched first for package:// meshes, "
              "separated by ':' (as gyro-sim run --package-path)"),
    Parameter("physics_rate", float, 1000.0, "physics steps per simulated second (Hz); 1/physics_rate is the step",
              1.0, MAX_PHYSICS_RATE),
    Parameter("publish_rate", float, 100.0,
              "publications per simulated second (Hz); physics_rate / publish_rate must be a whole number",
              0.01, MAX_PHYSICS_RATE),
    Parameter("real_time_factor", float, 1.0, "simulated seconds per wall second; 0 = as fast as possible",
              0.0, 1000.0),
    Parameter("integrator", str, "fixed",
              "fixed (rk4, or gauss4s while the scene is stiff for rk4: chosen for the scene and re-checked as it "
              "moves) | rk4 | lie4 | gauss4 | gauss4s | dop853 | radau | auto (fixed-step methods take one step per "
              "physics step)"),
    Parameter("backend", str, "auto",
              "dynamics: auto (numba-compiled when numba is installed, else numpy) | numba | numpy"),
    Parameter("rtol", float, 1e-8, "relative tolerance of adaptive integrators", 1e-14, 1.0),
    Parameter("atol", float, 1e-10, "absolute tolerance of adaptive integrators", 0.0, 1.0),
    Parameter("record", str, "", "MCAP file to record every published message and command to; empty = no recording; "
              "auto = gyro_sim_YYYYmmdd_HHMMSS.mcap here; {time} in a name = the start's date and time"),
    Parameter("command_timeout", float, 0.5,
              "simulated seconds without a good command after which the axis moments fall back to zero", 1e-3, 1e9),
    Parameter("duration", float, 0.0, "simulated seconds to run, then exit; 0 = until shut down", 0.0, 1e9),
    Parameter("publish_wrenches", bool, True,
              "publish ~/wrench/<joint> (computed only while someone listens or records)"),
    Parameter("publish_poses", bool, True, "publish ~/poses (computed only while someone listens or records)"),
    Parameter("stats_file", str, "", "write the run's timing statistics as JSON to this file at exit; empty = none"),
    Parameter("overwrite", bool, False, "replace existing record / stats_file files (never the scene file)"),
    Parameter("record_queue_mb", float, RECORD_QUEUE_MB,
              "most megabytes of records waiting for the log writer; when it falls further behind, the oldest "
              "publications waiting are dropped from the log (counted in /diagnostics), never commands or events",
              1.0, 4096.0),
    Parameter("frame_prefix", str, "",
              "put before every body's frame in /tf and the wrenches' frame_id (as robot_state_publisher's), "
              "e.g. robot1/ for a second robot on one /tf; world stays world"),
    Parameter("demo", bool, False,
              "drive every actuated axis with built-in sines scaled to the scene (recorded as commands are) "
              "until a command arrives on ~/axis_moments"),
    Parameter("lockstep", bool, False,
              "advance one control period (1/publish_rate) per command received on ~/axis_moments, then publish: "
              "simulated time goes at the controller's pace (real_time_factor not used); the initial state is "
              "published first, then the node waits for a command"),
    Parameter("hold", str, "none",
              "none | until_command: hold the initial state (published, time not running) until the first command "
              "arrives on ~/axis_moments, then run"),
    Parameter("thread_priority", float, 50.0,
              "SCHED_FIFO priority (1-99) of the physics thread while pacing in real time, where the system allows "
              "it (as ros2_control's thread_priority); 0 = the normal scheduler", 0.0, 99.0),
)


@dataclass(frozen=True)
class NodeConfig:
    """Validated parameters, plus what follows from them."""

    scene_path: Path
    scene: object  # gyro_sim.scene.records.Scene
    physics_rate: float
    publish_rate: float
    real_time_factor: float
    integrator: str
    backend: str
    rtol: float
    atol: float
    record: str
    command_timeout: float
    duration: float
    publish_wrenches: bool
    publish_poses: bool
    stats_file: str
    overwrite: bool = False
    thread_priority: float = 0.0
    record_queue_mb: float = RECORD_QUEUE_MB
    demo: bool = False
    lockstep: bool = False
    hold: str = "none"
    frame_prefix: str = ""
    lock: str = ""
    package_path: str = ""

    @property
    def dt(self) -> float:
        """The physics step (simulated s)."""
        return 1.0 / self.physics_rate

    @property
    def waits_for_command(self) -> bool:
        """The run starts at the first command (lock-step, or hold until_command)."""
        return self.lockstep or self.hold == "until_command"

    @property
    def steps_per_publish(self) -> int:
        return int(round(self.physics_rate / self.publish_rate))

    def as_dict(self) -> dict:
        """The parameters as given (for the log's metadata)."""
        return {p.name: getattr(self, p.name) if p.name != "scene" else str(self.scene_path) for p in PARAMETERS}


#: a frame_prefix: tf frame names do not start with "/" (tf2)
FRAME_PREFIX = re.compile(r"(?:[A-Za-z0-9_][A-Za-z0-9_/]*)?")
#: the value of `record` that names the log after the start's date and time
RECORD_AUTO = "auto"
#: what {time} in `record` becomes (the start's local date and time, to the second)
TIME_FORMAT = "%Y%m%d_%H%M%S"


def record_path(text: str, now: float | None = None) -> str:
    """The log file `record` names: "auto" is ``gyro_sim_{time}.mcap``; ``{time}`` is the
    date and time `now` (default: now) as YYYYmmdd_HHMMSS; any other text as it is."""
    import time

    if text == RECORD_AUTO:
        text = "gyro_sim_{time}.mcap"
    if "{time}" in text:
        text = text.replace("{time}", time.strftime(TIME_FORMAT, time.localtime(now)))
    return text


def _number_problem(p: Parameter, v) -> str | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return f"{p.name}: expected a number, got {v!r}"
    if not math.isfinite(v):
        return f"{p.name}: must be finite, got {v!r}"
    if p.low is not None and v < p.low:
        return f"{p.name}: must be >= {p.low:g}, got {v!r}"
    if p.high is not None and v > p.high:
        return f"{p.name}: must be <= {p.high:g}, got {v!r}"
    return None


def validate(values: dict) -> NodeConfig:
    """Check every parameter (missing ones take their default); raise ParameterError listing
    all problems, or return the NodeConfig with the scene loaded."""
    from gyro_sim.integrators import INTEGRATORS
    from gyro_sim.scene.load import SceneError, load_scene
    from gyro_sim.scene.commands import node_model_options as model_options
    from gyro_sim.paths import find_scene

    v = {p.name: values.get(p.name, p.default) for p in PARAMETERS}
    problems = []
    for p in PARAMETERS:
        if p.kind is float:
            msg = _number_problem(p, v[p.name])
            if msg:
                problems.append(msg)
            else:
                v[p.name] = float(v[p.name])
        elif p.kind is bool and not isinstance(v[p.name], bool):
            problems.append(f"{p.name}: expected true or false, got {v[p.name]!r}")
        elif p.kind is str and not isinstance(v[p.name], str):
            problems.append(f"{p.name}: expected a string, got {v[p.name]!r}")
    bad = {m.split(":")[0] for m in problems}
    if "thread_priority" not in bad and v["thread_priority"] != int(v["thread_priority"]):
        problems.append(f"thread_priority: must be a whole number (0-99), got {v['thread_priority']!r}")
    if not {"physics_rate", "publish_rate"} & bad:
        ratio = v["physics_rate"] / v["publish_rate"]
        if ratio < 1 - RATIO_TOLERANCE:
            problems.append(f"publish_rate: must not exceed physics_rate ({v['physics_rate']:g} Hz), "
                            f"got {v['publish_rate']:g}")
        elif abs(ratio - round(ratio)) > RATIO_TOLERANCE * ratio:
            lo, hi = v["physics_rate"] / math.ceil(ratio), v["physics_rate"] / math.floor(ratio)
            problems.append(
                f"publish_rate: physics_rate / publish_rate = {ratio:g} must be a whole number of physics steps "
                f"(with physics_rate {v['physics_rate']:g}: e.g. publish_rate {lo:g} or {hi:g})"
            )
    if "hold" not in bad and v["hold"] not in HOLDS:
        problems.append(f"hold: unknown {v['hold']!r}; valid: {', '.join(HOLDS)}")
    if not {"lockstep", "demo"} & bad and v["lockstep"] and v["demo"]:
        problems.append("demo: not with lockstep (the demo's commands would advance the lock-step node by themselves)")
    elif not {"hold", "demo"} & bad and v["hold"] == "until_command" and v["demo"]:
        problems.append("demo: not with hold until_command (the demo drives until a command comes, the hold waits "
                        "for one: the demo would never run)")
    if "integrator" not in bad and v["integrator"] not in INTEGRATORS:
        problems.append(f"integrator: unknown {v['integrator']!r}; valid: {', '.join(INTEGRATORS)}")
    if "backend" not in bad:
        from gyro_sim.dynamics.kernel import available
        from gyro_sim.dynamics.system import BACKENDS

        if v["backend"] not in BACKENDS:
            problems.append(f"backend: unknown {v['backend']!r}; valid: {', '.join(BACKENDS)}")
        elif v["backend"] == "numba" and not available():
            problems.append("backend: numba is not installed (use auto or numpy)")
    scene = scene_path = None
    if "scene" not in bad:
        if not v["scene"].strip():
            problems.append("scene: empty; give a scene file or a shipped scene name")
        else:
            try:
                scene_path = find_scene(v["scene"])
                scene = load_scene(scene_path, **model_options(v))
            except FileNotFoundError as exc:
                problems.append(f"scene: {exc}")
            except SceneError as exc:
                problems.append(f"scene: {scene_path}: {exc}")
    from gyro_sim.safe_paths import OutputError, check_output

    if "record" not in bad:
        v["record"] = record_path(v["record"])
    if "frame_prefix" not in bad and not FRAME_PREFIX.fullmatch(v["frame_prefix"]):
        problems.append(f"frame_prefix: letters, digits, _ and / not at the start (a tf frame name's start), "
                        f"got {v['frame_prefix']!r}")
    force = v["overwrite"] if "overwrite" not in bad else False
    for name in ("record", "stats_file"):
        if name not in bad and v[name]:
            try:  # exists (unless overwrite), the scene file, a directory, parent missing/unwritable
                check_output(v[name], inputs=[scene_path], force=force, what=name)
            except OutputError as exc:
                problems.append(str(exc))
    if not {"record", "stats_file"} & bad and v["record"] and v["stats_file"] and \
            Path(v["record"]).expanduser().resolve() == Path(v["stats_file"]).expanduser().resolve():
        problems.append(f"stats_file: the same file as record ({v['record']})")
    if "record" not in bad and v["record"]:
        try:
            import mcap  # noqa: F401

            from gyro_sim.log import mcap_log  # noqa: F401
        except ImportError as exc:
            problems.append(f"record: recording needs the mcap package ({exc})")
    if problems:
        raise ParameterError("\n".join(problems))
    v = dict(v)
    v["record"] = str(Path(v["record"]).expanduser().resolve()) if v["record"] else ""
    del v["scene"]
    return NodeConfig(scene_path=scene_path, scene=scene, **v)


# --- the command line, read before rclpy starts (gyro_sim_node --help, misspelt parameters) ----------

#: node name the overrides must address (params files: `gyro_sim:` or `/gyro_sim:`, or wildcards)
NODE_NAME = "gyro_sim"
#: parameters every rclpy node declares itself; overriding them is legitimate
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")
#: prefixes of parameters rclpy reads for itself (QoS overrides of publishers and subscriptions)
RCLPY_PREFIXES = ("qos_overrides.",)
#: ROS arguments followed by a value that is not a parameter (rcl_arguments.c)
_ROS_OPTIONS_WITH_VALUE = ("-r", "--remap", "-e", "--enclave", "--log-level", "--log-config-file",
                           "--log-file-name")
_HELP_FLAGS = ("-h", "--help")
_TYPE_NAMES = {float: "double", str: "string", bool: "bool"}


def _yaml_value(text: str):
    """A `-p` value as rcl reads it (YAML), e.g. `500.0` -> 500.0, `true` -> True."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def _node_matches(key: str) -> bool:
    """Whether a params file's top-level key addresses this node (`gyro_sim`, `/gyro_sim`, `/**`)."""
    import fnmatch

    pattern = "/" + str(key).lstrip("/")
    return fnmatch.fnmatchcase("/" + NODE_NAME, pattern.replace("**", "*"))


def _flatten(prefix: str, value, out: dict) -> None:
    """Nested mappings under ros__parameters name dotted parameters (`a: {b: 1}` -> `a.b`)."""
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = value


def read_params_file(path: str) -> dict:
    """The parameters a ROS 2 params file gives this node (name -> value); ParameterError if
    the file is missing or not such a file."""
    import yaml

    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except FileNotFoundError:
        raise ParameterError(f"--params-file {path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterError(f"--params-file {path}: cannot read ({exc})") from None
    except yaml.YAMLError as exc:
        raise ParameterError(f"--params-file {path}: not YAML ({str(exc).splitlines()[0]})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ParameterError(f"--params-file {path}: expected `{NODE_NAME}: ros__parameters: ...` at the top")
    values: dict = {}
    for node, body in data.items():
        if not _node_matches(node):
            continue
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters", {}), dict):
            raise ParameterError(f"--params-file {path}: {node}: expected `ros__parameters:` with a mapping")
        _flatten("", body.get("ros__parameters") or {}, values)
    return values


def parse_ros_argv(argv) -> tuple[bool, dict]:
    """Read the node's command line as rcl will: (help asked, parameter overrides).

    `argv` is what follows the program name (the program name itself, if first and not an
    option, is skipped too). Overrides are `-p name:=value` / `--param name:=value` (also
    `-p gyro_sim:name:=value`) and `--params-file FILE` inside `--ros-args ... [--]`; a later
    one wins, as in rcl. Help is `-h` or `--help` anywhere. ParameterError for a `-p` without
    `:=` or a params file that cannot be read.
    """
    args = list(argv)
    help_asked = any(a in _HELP_FLAGS for a in args)
    values: dict = {}
    in_ros = False
    i = 0
    while i < len(args):
        a = args[i]
        if a == "--ros-args":
            in_ros = True
        elif a == "--" and in_ros:
            in_ros = False
        elif in_ros and a in ("-p", "--param"):
            if i + 1 >= len(args) or ":=" not in args[i + 1]:
                raise ParameterError(f"{a} needs NAME:=VALUE, got {args[i + 1] if i + 1 < len(args) else 'nothing'}")
            name, _, text = args[i + 1].partition(":=")
            node, _, name = name.rpartition(":")
            if not node or _node_matches(node):
                values[name] = _yaml_value(text)
            i += 1
        elif in_ros and a == "--params-file":
            if i + 1 >= len(args):
                raise ParameterError("--params-file needs a file")
            values.update(read_params_file(args[i + 1]))
            i += 1
        elif in_ros and a in _ROS_OPTIONS_WITH_VALUE:
            i += 1
        i += 1
    return help_asked, values


def unknown_parameters(values: dict) -> list[str]:
    """One line per override that names no parameter of the node, with the closest name."""
    import difflib

    names = [p.name for p in PARAMETERS]
    lines = []
    for name in values:
        if name in names or name in RCLPY_PARAMETERS or name.startswith(RCLPY_PREFIXES):
            continue
        close = difflib.get_close_matches(name, names, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else f" (parameters: {', '.join(names)})"
        lines.append(f"unknown parameter {name!r}{hint}")
    return lines


def _show(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return repr(v) if v else '""'
    return repr(float(v))  # as a -p value must be written: 1000.0, not 1000


def help_text() -> str:
    """`gyro_sim_node --help`: usage and every parameter (name, type, default, range), one line each."""
    rows = []
    for p in PARAMETERS:
        rng = "" if p.low is None and p.high is None else (
            f"[{'' if p.low is None else f'{p.low:g}'}, {'' if p.high is None else f'{p.high:g}'}]")
        rows.append((p.name, _TYPE_NAMES.get(p.kind, p.kind.__name__), _show(p.default), rng, p.description))
    widths = [max(len(r[c]) for r in rows) for c in range(4)]
    head = ("usage: gyro_sim_node [-h] [--ros-args [--params-file FILE] [-p NAME:=VALUE ...]]\n\n"
            "The gyro_sim node: simulates a chain of gyrostats in real time, takes axis moments on\n"
            "~/axis_moments, publishes joint_states, robot_description, /clock, /tf, ~/wrench/<joint>,\n"
            "~/poses, /diagnostics (-r __ns:=/robot1 puts joint_states, robot_description and ~/ under\n"
            "/robot1), optionally records an MCAP log. A later -p wins over --params-file; an unknown\n"
            "name or an invalid value stops the node at start (exit 2).\n\n"
            "example:\n"
            "  gyro_sim_node --ros-args --params-file config/params.yaml -p record:=live.mcap -p duration:=20.0\n"
            "  gyro_sim_node --ros-args --params-file config/params.yaml -p demo:=true -p record:=auto\n"
            "  gyro_sim_node --ros-args -p scene:=rw_pendulum -p lockstep:=true   (one control period per\n"
            "      command on ~/axis_moments: a controller of any speed closes the loop exactly)\n\n"
            "parameters (name, type, default, range, meaning):\n")
    lines = ["  " + "  ".join(r[c].ljust(widths[c]) for c in range(4)) + "  " + r[4] for r in rows]
    return head + "\n".join(line.rstrip() for line in lines) + "\n"


def preflight(argv, stream_out=None, stream_err=None) -> int | None:
    """What gyro_sim_node does before it starts rclpy: `--help` -> print the parameters, 0;
    an unknown parameter or an unreadable params file -> one line each on stderr, 2; else
    compile the numba kernels if their cache is cold (saying so), or with backend "auto" start
    their compile in the background (gyro_sim.warmup.start_deferred), and return None (go on)."""
    import sys

    out = stream_out or sys.stdout
    err = stream_err or sys.stderr
    args = list(argv)
    if args and not args[0].startswith("-"):
        args = args[1:]  # the program name (rclpy.init takes sys.argv whole)
    try:
        help_asked, values = parse_ros_argv(args)
    except ParameterError as exc:
        if any(a in _HELP_FLAGS for a in args):
            out.write(help_text())
            return 0
        err.write(f"gyro_sim_node: {exc}\n")
        return 2
    if help_asked:
        out.write(help_text())
        return 0
    unknown = unknown_parameters(values)
    if unknown:
        err.write("".join(f"gyro_sim_node: {line}\n" for line in unknown))
        return 2
    backend = values.get("backend", "auto")
    if backend != "numpy":
        from gyro_sim.warmup import precompile, start_deferred

        integrator = str(values.get("integrator", "fixed"))
        # "auto" on a cold cache: the kernels compile in the background while the run steps on
        # numpy (gyro_sim.ros.node checks that the scene fits); else compiled here, now
        if backend != "auto" or not start_deferred(integrator, err, "gyro_sim_node"):
            precompile(err, prog="gyro_sim_node", integrator=integrator)
    return None
