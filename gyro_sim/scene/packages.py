"""``package://NAME/PATH`` URIs of robot descriptions, resolved as ROS does (docs/models.md,
"Meshes and package:// URIs").

A package NAME is looked for in this order; the first match wins:

1. each ``--package-path`` directory (``load_scene(..., package_path=...)``), in the order
   given: the directory itself when its ``package.xml`` names NAME or its name is NAME,
   ``DIR/NAME``, or a directory below it (at most ``CRAWL_DEPTH`` levels) whose
   ``package.xml`` names NAME;
2. the ament index (ROS 2): the first prefix of ``AMENT_PREFIX_PATH`` holding
   ``share/ament_index/resource_index/packages/NAME`` gives ``PREFIX/share/NAME``;
3. ``ROS_PACKAGE_PATH`` (ROS 1): the directory, in or below an entry, whose ``package.xml``
   has ``<name>NAME</name>``;
4. the nearest directory above the model file whose ``package.xml`` names NAME (a
   description used from its own source tree).

``file://`` URIs are paths; a relative path is relative to the model file's directory.
Nothing here raises: a URI that cannot be resolved gives None and the caller says so.
"""
from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

__all__ = ["CRAWL_DEPTH", "PackageResolver"]

#: how deep below a package path or a ROS_PACKAGE_PATH entry a package.xml is looked for
CRAWL_DEPTH = 4
#: the head of a package.xml read for its <name>
_HEAD = 16384
_NAME = re.compile(r"<name>\s*([^<\s]+)\s*</name>")


def _package_name(directory: str) -> str | None:
    """The <name> of `directory`'s package.xml, or None without one."""
    try:
        with open(os.path.join(directory, "package.xml"), "rb") as stream:
            head = stream.read(_HEAD).decode("utf-8", "replace")
    except OSError:
        return None
    match = _NAME.search(re.sub(r"<!--.*?-->", "", head, flags=re.DOTALL))
    return match.group(1) if match else None


def _crawl(root: str, name: str, depth: int = CRAWL_DEPTH) -> str | None:
    """The first directory in or below `root` (breadth first, at most `depth` levels, hidden
    directories skipped, a package's own subdirectories not entered) whose package.xml names
    `name`."""
    level = [root]
    for _ in range(depth + 1):
        below = []
        for directory in level:
            found = _package_name(directory)
            if found == name:
                return directory
            if found is not None:
                continue  # a package: its subdirectories are its own
            try:
                entries = sorted(os.scandir(directory), key=lambda e: e.name)
            except OSError:
                continue
            below += [e.path for e in entries if not e.name.startswith(".") and e.is_dir()]
        level = below
    return None


@dataclass
class PackageResolver:
    """Resolves a model's mesh URIs; remembers where each package was found (`found`)."""

    model_path: str
    package_path: Sequence[str] = ()
    environ: dict | None = None  # default os.environ
    found: dict[str, tuple[str, str]] = field(default_factory=dict)  # name -> (dir, how)

    def package(self, name: str) -> tuple[str, str] | None:
        """Where package `name` is, and how it was found; None when nowhere."""
        if name in self.found:
            return self.found[name]
        env = os.environ if self.environ is None else self.environ
        hit = None
        for directory in self.package_path:
            directory = os.path.abspath(os.path.expanduser(os.fspath(directory)))
            if _package_name(directory) == name or (os.path.basename(directory) == name
                                                    and os.path.isdir(directory)):
                hit = (directory, "--package-path")
            elif os.path.isdir(os.path.join(directory, name)):
                hit = (os.path.join(directory, name), "--package-path")
            else:
                below = _crawl(directory, name) if os.path.isdir(directory) else None
                hit = (below, "--package-path") if below else None
            if hit:
                break
        if hit is None:
            for prefix in filter(None, env.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
                marker = os.path.join(prefix, "share", "ament_index", "resource_index", "packages", name)
                if os.path.exists(marker):
                    hit = (os.path.join(prefix, "share", name), "the ament index (AMENT_PREFIX_PATH)")
                    break
        if hit is None:
            for entry in filter(None, env.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
                below = _crawl(entry, name) if os.path.isdir(entry) else None
                if below:
                    hit = (below, "ROS_PACKAGE_PATH")
                    break
        if hit is None:
            directory = os.path.dirname(os.path.abspath(self.model_path))
            while True:
                if _package_name(directory) == name:
                    hit = (directory, "the package.xml above the model")
                    break
                parent = os.path.dirname(directory)
                if parent == directory:
                    break
                directory = parent
        if hit is not None:
            self.found[name] = hit
        return hit

    def resolve(self, uri: str, base: str | None = None) -> tuple[str | None, str]:
        """The file a URI names (None when its package is not found) and what it names (the
        URI itself, for messages). `base`: the directory a relative path is relative to
        (default the model file's)."""
        if uri.startswith("package://"):
            name, _, rest = uri[len("package://"):].partition("/")
            where = self.package(name)
            return (os.path.join(where[0], rest) if where else None), uri
        uri = uri.removeprefix("file://")
        path = os.path.expanduser(uri)
        if not os.path.isabs(path):
            path = os.path.join(base or os.path.dirname(os.path.abspath(self.model_path)), path)
        return os.path.normpath(path), uri

    def notes(self) -> list[str]:
        """One line per package found: where, and how."""
        return [f"package {name!r}: {where} (from {how})" for name, (where, how) in self.found.items()]
