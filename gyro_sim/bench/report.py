"""Writing a report's files: Markdown, JSON and the PNG plot (each `gyro-sim bench` command)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable


def write_report(out: str | Path, name: str, markdown: str, data: Any, plot: Callable[[str], None]) -> list[Path]:
    """Write <out>/<name>.md, .json and .png (the plot is skipped without matplotlib); print
    and return the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.md").write_text(markdown)
    (out / f"{name}.json").write_text(json.dumps(data, indent=1, default=float))
    written = [out / f"{name}.md", out / f"{name}.json"]
    try:
        plot(str(out / f"{name}.png"))
        written.append(out / f"{name}.png")
    except ImportError:
        print("(install matplotlib for the plot)")
    print("\nwrote " + ", ".join(str(w) for w in written))
    return written
