"""ROS 2 message definitions as MCAP schemas (encoding ``ros2msg``).

An MCAP schema of the ROS 2 profile holds the *concatenated* definition: the type's own
``.msg`` text, then every type it uses, directly or not, each after a separator line of 80
``=`` and a ``MSG: pkg/Type`` line (the layout rosbag2 writes, which rosbags, mcap-ros2-support
and rerun parse).

The ``.msg`` texts come from the installed message packages when there are any
(``<prefix>/share/<pkg>/msg/<Type>.msg`` for the prefixes of ``AMENT_PREFIX_PATH`` and
``sys.prefix``: the layout of apt-installed ROS and of the ``ros-jazzy-*`` wheels), else from
the copies shipped in ``gyro_sim/msgs/msg/<pkg>/<Type>.msg`` so that offline runs need no ROS.
``tf2_msgs/TFMessage`` is not on PyPI: only the shipped copy exists unless ROS is installed.
"""
from __future__ import annotations

import functools
import os
import re
import sys
from pathlib import Path

#: the separator rosbag2 writes between the definitions of a concatenated schema
SEPARATOR = "=" * 80
#: the primitive types of the .msg language (no definition file)
PRIMITIVES = frozenset(
    "bool byte char float32 float64 int8 uint8 int16 uint16 int32 uint32 int64 uint64 string wstring".split()
)
#: the shipped copies
SHIPPED = Path(__file__).resolve().parent / "msg"


def normalize(msgtype: str) -> str:
    """``pkg/msg/Type`` (the schema name of the ROS 2 profile) from ``pkg/Type`` or itself."""
    parts = msgtype.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and parts[1] == "msg":
        return msgtype
    raise ValueError(f"not a message type: {msgtype!r} (expected pkg/msg/Type)")


def _share_dirs() -> list[Path]:
    dirs = []
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share")
    dirs.append(Path(sys.prefix) / "share")
    return dirs


@functools.lru_cache(maxsize=None)
def msg_text(msgtype: str, *, shipped_only: bool = False) -> str:
    """The ``.msg`` text of one type (``pkg/msg/Type``): installed first, else shipped."""
    pkg, _, name = normalize(msgtype).split("/")
    candidates = [] if shipped_only else [d / pkg / "msg" / f"{name}.msg" for d in _share_dirs()]
    candidates.append(SHIPPED / pkg / f"{name}.msg")
    for path in candidates:
        if path.is_file():
            return path.read_text()
    raise LookupError(f"no definition of {msgtype} (looked in {', '.join(str(c.parent) for c in candidates)})")


# type (bounded string, array suffix), name, then a constant (=value) or a default value
_FIELD = re.compile(r"^\s*([A-Za-z][\w/]*)(?:<=\d+)?(\[[^\]]*\])?\s+([A-Za-z]\w*)\s*(=.*)?(?:\s+\S.*)?$")


def dependencies(pkg: str, text: str) -> list[str]:
    """The non-primitive field types of one ``.msg`` text, as ``pkg/msg/Type``, in order."""
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        m = _FIELD.match(line)
        if not m or m.group(4):  # a constant: always primitive
            continue
        ftype = m.group(1)
        if ftype in PRIMITIVES:
            continue
        full = normalize(ftype if "/" in ftype else f"{pkg}/{ftype}")
        if full not in out:
            out.append(full)
    return out


@functools.lru_cache(maxsize=None)
def definition(msgtype: str, *, shipped_only: bool = False) -> str:
    """The concatenated definition of `msgtype` (the schema data of an MCAP channel)."""
    root = normalize(msgtype)
    order: list[str] = []
    texts: dict[str, str] = {}

    def visit(t: str) -> None:  # depth first, each type once, in order of first use
        if t in texts:
            return
        texts[t] = msg_text(t, shipped_only=shipped_only)
        order.append(t)
        for dep in dependencies(t.split("/")[0], texts[t]):
            visit(dep)

    visit(root)
    parts = [texts[root].rstrip("\n")]
    for t in order[1:]:
        pkg, _, name = t.split("/")
        parts.append(f"{SEPARATOR}\nMSG: {pkg}/{name}\n{texts[t].rstrip(chr(10))}")
    return "\n".join(parts) + "\n"


def closure(msgtypes) -> list[str]:
    """Every type the given ones use, themselves included (for shipping copies)."""
    seen: list[str] = []

    def visit(t: str) -> None:
        if t in seen:
            return
        seen.append(t)
        for dep in dependencies(t.split("/")[0], msg_text(t)):
            visit(dep)

    for t in msgtypes:
        visit(normalize(t))
    return seen
