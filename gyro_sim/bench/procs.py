"""Other processes seen from /proc (Linux), for the benchmarks and the tests that watch a node
and its log writer."""
from __future__ import annotations

from pathlib import Path


def children(pid: int) -> list[int]:
    """The processes `pid` started (/proc/PID/task/*/children): a node's log writer."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(x) for x in (task / "children").read_text().split()]
        except OSError:  # the thread ended meanwhile
            pass
    return out


def running(pid: int) -> bool:
    """Whether process `pid` still runs: one of its threads has not ended. A zombie, ended and not
    yet reaped, does not run; but a thread group's leader shows as a zombie while its other
    threads still end, and the process's files (its locks) are closed only when the last one
    has: every thread is looked at."""
    def ended(stat: Path) -> bool:
        return stat.read_text().rsplit(")", 1)[1].split()[0] in ("Z", "X")

    try:
        tasks = list(Path(f"/proc/{pid}/task").glob("*/stat"))
        if not tasks:
            return not ended(Path(f"/proc/{pid}/stat"))
        alive = False
        for task in tasks:
            try:
                alive = alive or not ended(task)
            except (OSError, IndexError):  # that thread has gone meanwhile
                continue
        return alive
    except (OSError, IndexError):
        return False


def rss_mb(pid: int) -> float:
    """Resident memory of process `pid` (MB); NaN when /proc gives none (a zombie)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")
