"""The documentation against the code it describes.

- docs/scene-format.md documents exactly the keys the scene loader accepts, level by level, and
  the loader enforces exactly those tables;
- docs/ros-interface.md documents every node parameter and every diagnostics key;
- README.md stays short;
- nothing in the repository speaks of the work's history (numbered work periods, tracker
  numbers) or cites files outside the repository;
- every relative link, file path, module name and command the README and docs/ show exists
  or parses.

The key tables come from the code (`gyro_sim.scene.load`, `gyro_sim.ros.params`,
`gyro_sim.msgs.messages`), the documented keys from the Markdown: neither is copied into this
file.
"""
from __future__ import annotations

import copy
import importlib
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
SCENE_FORMAT = DOCS / "scene-format.md"
ROS_INTERFACE = DOCS / "ros-interface.md"
#: the README is for a newcomer: at most this many lines, the rest in docs/
README_MAX_LINES = 250
#: the pages a reader is sent to
DOC_PAGES = sorted(DOCS.glob("*.md"))
MARKDOWN = [README, ROOT / "CHANGELOG.md", *DOC_PAGES]
#: the shipped scenes and sweeps: their comments name modules and files too
CONFIG_FILES = sorted((ROOT / "config").rglob("*.yaml"))

# --- (a) scene keys -------------------------------------------------------------------------------------

#: heading of a section of docs/scene-format.md -> (the loader's table of that level's keys,
#: the key path the loader reports errors under in `valid_scene()`)
SCENE_SECTIONS = {
    "Top level": ("TOP_KEYS", ""),
    "`base`": ("BASE_KEYS", "base"),
    "`base.motion`": ("MOTION_KEYS", "base.motion"),
    "`bodies[k]`": ("BODY_KEYS", "bodies[0]"),
    "`bodies[k].joint`": ("JOINT_KEYS", "bodies[0].joint"),
    "`bodies[k].joint.spring`": ("SPRING_KEYS", "bodies[1].joint.spring"),
    "`bodies[k].joint.servo`": ("SERVO_KEYS", "bodies[1].joint.servo"),
    "`bodies[k].joint.motor`": ("MOTOR_KEYS", "bodies[1].joint.motor"),
    "`bodies[k].inertia`": ("INERTIA_KEYS", "bodies[0].inertia"),
    "`bodies[k].rotors[i]`": ("ROTOR_KEYS", "bodies[0].rotors[0]"),
    "`friction`": ("FRICTION_KEYS", "bodies[0].rotors[0].friction"),
    "`bodies[k].initial`": ("INITIAL_KEYS", "bodies[0].initial"),
    "`bodies[k].visual`": ("VISUAL_KEYS", "bodies[0].visual"),
    "`imus[j]`": ("IMU_KEYS", "imus[0]"),
}
#: a key no level accepts
UNKNOWN_KEY = "not_a_scene_key"


@pytest.fixture(scope="module")
def loader():
    """The scene loader, by the module path the docs name."""
    return importlib.import_module("gyro_sim.scene.load")


def documented_sections(path: Path) -> dict[str, set[str]]:
    """heading -> the keys in the first column of the tables under it (`key` in backticks)."""
    sections: dict[str, set[str]] = {}
    current = None
    for line in path.read_text(encoding="utf-8").splitlines():
        heading = re.match(r"#{2,4} (.+?)\s*$", line)
        if heading:
            current = heading.group(1)
            continue
        row = re.match(r"\|\s*`([^`]+)`\s*\|", line)
        if row and current is not None:
            sections.setdefault(current, set()).add(row.group(1))
    return sections


def valid_scene() -> dict:
    """A scene holding every level of the format once: a moving base, one spherical body with
    an inertia, a rotor, an initial state and a visual, and a hinge with a spring, a servo and a geared motor."""
    return {
        "name": "every level",
        "gravity": [0.0, 0.0, -9.81],
        "base": {"type": "moving", "position": [0.0, 0.0, 0.0],
                 "motion": {"type": "sine", "amplitude": [0.0, 0.0, 0.01], "frequency": 10.0}},
        "bodies": [{
            "name": "top",
            "joint": {"type": "spherical"},
            "mass": 1.0,
            "com": [0.0, 0.0, 0.1],
            "inertia": {"axial": 0.004, "transverse": 0.015},
            "rotors": [{"name": "wheel", "axis": [0.0, 0.0, 1.0], "mass": 0.1, "axial_inertia": 1e-4,
                        "transverse_inertia": 1e-4, "mode": "torque", "friction": {"viscous": 1e-6}}],
            "initial": {"euler": [0.0, 0.5, 0.0]},
            "visual": {"radius": 0.02},
            "next_joint": [0.0, 0.0, 0.2],
        }, {
            "name": "arm",
            "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0],
                      "spring": {"stiffness": 2.0, "reference": 0.1}, "servo": {"gain": 2.0},
                      "motor": {"inertia": 1e-4, "gear": 10.0}},
            "mass": 0.5,
            "com": [0.0, 0.0, 0.1],
            "inertia": {"axial": 0.001, "transverse": 0.009},
        }],
        "imus": [{"name": "imu", "body": "top"}],
    }


def level(scene: dict, key_path: str) -> dict:
    """The mapping at `key_path` ("" the top, "bodies[0].rotors[0]", ...) of `scene`."""
    node = scene
    for part in filter(None, key_path.split(".")):
        name, *indices = re.findall(r"[^\[\]]+", part)
        node = node[name]
        for index in indices:
            node = node[int(index)]
    return node


def scene_errors(loader, scene: dict) -> list[str]:
    try:
        loader.load_scene(scene)
    except loader.SceneError as exc:
        return list(exc.errors)
    return []


def test_every_key_table_of_the_loader_has_its_section():
    """Every module-level `*_KEYS` tuple of the loader is a documented level or part of one
    (the Euler, quaternion and hinge forms are parts of `initial`): a new level of the format
    cannot go undocumented."""
    loader = importlib.import_module("gyro_sim.scene.load")
    levels = {name for name, _ in SCENE_SECTIONS.values()}
    tables = {name: value for name, value in vars(loader).items()
              if name.endswith("_KEYS") and isinstance(value, tuple)}
    assert levels <= set(tables), f"tables the docs expect but the loader lacks: {levels - set(tables)}"
    for name, keys in tables.items():
        assert name in levels or any(set(keys) <= set(tables[lv]) for lv in levels), (
            f"gyro_sim.scene.load.{name} {keys} is no level of docs/scene-format.md")


@pytest.mark.parametrize("heading", list(SCENE_SECTIONS))
def test_scene_format_documents_exactly_the_accepted_keys(loader, heading):
    table, _ = SCENE_SECTIONS[heading]
    accepted = set(getattr(loader, table))
    documented = documented_sections(SCENE_FORMAT).get(heading, set())
    assert accepted - documented == set(), f"{heading}: accepted by the loader, not documented"
    assert documented - accepted == set(), f"{heading}: documented, not accepted by the loader"


@pytest.mark.parametrize("heading", list(SCENE_SECTIONS))
def test_the_loader_accepts_the_documented_keys_and_no_other(loader, heading):
    """Behaviour, not only the tables: at each level the documented keys never raise
    "unknown key" and an undocumented one does."""
    _, key_path = SCENE_SECTIONS[heading]
    assert scene_errors(loader, valid_scene()) == []
    prefix = f"{key_path}." if key_path else ""
    for key in documented_sections(SCENE_FORMAT)[heading]:
        scene = copy.deepcopy(valid_scene())
        level(scene, key_path).setdefault(key, None)  # null = absent, but its name is checked
        unknown = [e for e in scene_errors(loader, scene) if e.startswith(f"{prefix}{key}: unknown key")]
        assert unknown == [], unknown
    scene = copy.deepcopy(valid_scene())
    level(scene, key_path)[UNKNOWN_KEY] = 1.0
    assert any(e.startswith(f"{prefix}{UNKNOWN_KEY}: unknown key") for e in scene_errors(loader, scene))


# --- (b) the README is short --------------------------------------------------------------------------

def test_readme_is_short():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"


# --- (c) the product speaks of itself only --------------------------------------------------------------

#: where the product's words are
WORDED = ("README.md", "CHANGELOG.md", "docs", "gyro_sim", "test", "config")
WORDED_SUFFIXES = {".py", ".md", ".yaml", ".yml", ".txt", ".msg"}
#: files of the project's surroundings, not of the repository (built from parts so that this
#: file does not match itself)
OUTSIDE = ("SPEC" + ".md", "ROS_ON_PYPI" + ".md", ".." + "/shared")
#: history and outside references (built from parts, as above); "session" stays free for its
#: other meanings (pytest's scope="session", a test session)
FORBIDDEN = {
    "a numbered or relative work period": re.compile(
        r"\b" + "sess" + r"ions?\s+\d|\b(?:this|last|previous|earlier|next|former|prior|same)\s+" + "sess" + r"ions?\b",
        re.IGNORECASE),
    "a tracker number": re.compile(r"\b" + "iss" + r"ues?\s*#?\d+", re.IGNORECASE),
    "a file outside the repository": re.compile("|".join(re.escape(name) for name in OUTSIDE)),
}


def worded_files() -> list[Path]:
    out = []
    for name in WORDED:
        path = ROOT / name
        if path.is_file():
            out.append(path)
        elif path.is_dir():
            out += sorted(p for p in path.rglob("*") if p.is_file() and p.suffix in WORDED_SUFFIXES
                          and "__pycache__" not in p.parts)
    return out


def test_no_history_and_no_outside_references():
    found = []
    for path in worded_files():
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            for what, pattern in FORBIDDEN.items():
                match = pattern.search(line)
                if match:
                    found.append(f"{path.relative_to(ROOT)}:{number}: {what}: {match.group(0)!r}")
    assert found == [], f"{len(found)} lines:\n" + "\n".join(found)


# --- (d) links, paths, modules and commands the docs show exist ----------------------------------------

def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    in_code = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
        heading = None if in_code else re.match(r"#{1,6} (.+?)\s*$", line)
        if heading:
            base = slug(heading.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(path: Path) -> list[str]:
    return re.findall(r"\]\(([^)\s]+)\)", path.read_text(encoding="utf-8"))


@pytest.mark.parametrize("page", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_to_existing_files(page):
    for link in links(page):
        if "://" in link or link.startswith("mailto:"):
            continue
        target, _, anchor = link.partition("#")
        file = (page.parent / target).resolve() if target else page
        assert file.is_relative_to(ROOT), f"{page.name}: {link} leaves the repository"
        assert file.exists(), f"{page.name}: {link} does not exist"
        if anchor and file.suffix == ".md":
            assert anchor in anchors(file), f"{page.name}: {link}: no heading #{anchor} in {file.name}"


#: a repository path in running text: gyro_sim/..., test/..., config/..., docs/...
REPO_PATH = re.compile(r"(?<![\w/.-])((?:gyro_sim|test|config|docs|launch)/[\w./-]*\w)")
#: a dotted module name of the package
MODULE = re.compile(r"(?<![\w./])gyro_sim(?:\.[A-Za-z_]\w*)+")


def module_file(name: str) -> Path | None:
    """The source file of module `name` in this repository (not wherever it may be installed)."""
    path = ROOT.joinpath(*name.split("."))
    for candidate in (path.with_suffix(".py"), path / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


@pytest.mark.parametrize("page", MARKDOWN + CONFIG_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_named_files_and_modules_exist(page):
    """Paths (`gyro_sim/msgs/messages.py`) and modules (`gyro_sim.scene.load.load_scene`: a
    module and, at most, one name it defines) that a page names are in the repository."""
    text = page.read_text(encoding="utf-8")
    for path in sorted(set(REPO_PATH.findall(text))):
        assert (ROOT / path).exists(), f"{page.name} names {path}, which does not exist"
    for name in sorted(set(MODULE.findall(text))):
        if name.endswith(".py"):  # a file name (`gyro_sim.launch.py`), not a module
            continue
        parts = name.split(".")
        source = module_file(name)
        if source is None:
            source = module_file(".".join(parts[:-1]))
            assert source is not None, f"{page.name} names {name}: no such module in the repository"
            assert re.search(rf"^(?:def |class )?{parts[-1]}\b", source.read_text(encoding="utf-8"), re.M), (
                f"{page.name} names {name}: {source.relative_to(ROOT)} defines no {parts[-1]}")


#: Markdown files under these names are references by name to the repository's own pages
PAGE_REFERENCE = re.compile(r"(?<![\w/.-])((?:docs/)?[A-Z][A-Z_]*\.md|docs/[\w-]+\.md)\b")


def test_pages_named_in_the_code_exist():
    """The code and tests cite pages by name ("theory.md section 5", `docs/integrators.md`): each
    must exist under that name (at the top level or in docs/)."""
    stale = []
    for path in worded_files():
        for name in set(PAGE_REFERENCE.findall(path.read_text(encoding="utf-8", errors="replace"))):
            if name in OUTSIDE:  # test_no_history_and_no_outside_references names those
                continue
            if not ((ROOT / name).exists() or (DOCS / Path(name).name).exists()):
                stale.append(f"{path.relative_to(ROOT)}: {name}")
    assert stale == [], "pages that do not exist:\n" + "\n".join(sorted(stale))


def shown_commands(page: Path) -> list[str]:
    """The `gyro-sim ...` and `gyro_sim_node ...` command lines of a page's code blocks
    (indented or fenced), without comments and optional brackets, as test_examples collects the
    README's."""
    out, in_code = [], False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_code = not in_code
            continue
        if not (in_code or line.startswith("    ")):
            continue
        for segment in line.split(" && "):
            segment = segment.strip()
            if segment.startswith(("gyro-sim ", "gyro_sim_node ")):
                segment = re.sub(r"\s+#.*$", "", segment)
                out.append(re.sub(r"\[([^\[\]]*)\]", r"\1", segment).strip())
    return out


@pytest.mark.parametrize("page", DOC_PAGES, ids=lambda p: p.name)
@pytest.mark.slow
def test_commands_in_the_docs_parse(page):
    from gyro_sim.cli import build_parser
    from gyro_sim.ros.params import parse_ros_argv, unknown_parameters

    for line in shown_commands(page):
        program, *argv = shlex.split(line)
        if program == "gyro_sim_node":
            help_asked, values = parse_ros_argv(argv)
            assert not help_asked and unknown_parameters(values) == [], f"{page.name}: `{line}`"
            continue
        try:
            build_parser().parse_args(argv)
        except SystemExit as exc:
            pytest.fail(f"{page.name}: `{line}` does not parse (exit {exc.code})")


# --- the node's reference --------------------------------------------------------------------------------

def test_ros_interface_documents_every_parameter():
    from gyro_sim.ros.params import PARAMETERS

    text = ROS_INTERFACE.read_text(encoding="utf-8")
    documented = set(re.findall(r"^\|\s*`(\w+)`\s*\|\s*(?:double|string|bool)\s*\|", text, re.M))
    assert documented == {p.name for p in PARAMETERS}


def test_ros_interface_documents_every_diagnostics_key():
    messages = importlib.import_module("gyro_sim.msgs.messages")
    text = ROS_INTERFACE.read_text(encoding="utf-8")
    keys = set(messages.STRING_KEYS) | {messages.WORK_KEY, messages.FRICTION_WORK_KEY, messages.SATURATED_KEY,
                                        messages.BALANCE_KEY, messages.BALANCE_REL_KEY,
                                        messages.ERROR_ESTIMATE_KEY, messages.SIM_TIME_KEY,
                                        "<invariant>" + messages.DRIFT_SUFFIX, messages.axis_moment_key("<axis>")}
    missing = sorted(k for k in keys if f"`{k}`" not in text)
    for stem, unit in messages.INVARIANT_KEYS.values():  # a scalar, or a vector by components
        if f"`{stem}_{unit}`" not in text and f"`{stem}_{{x,y,z}}_{unit}`" not in text:
            missing.append(f"{stem}_{unit}")
    assert missing == [], f"diagnostics keys not in docs/ros-interface.md: {missing}"
