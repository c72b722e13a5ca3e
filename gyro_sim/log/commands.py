"""`gyro-sim recover`: the log subcommand that needs nothing beyond the log layer (`run --record`
lives in cli.py, `view` in gyro_sim.viz.commands, `replay` in cli.py), and `input_file`, the
check of a command's input log that all of them share.

Registered by :func:`register` (see ``gyro_sim.cli.PLUGINS``).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path


def _err(cmd: str, msg) -> None:
    print(f"gyro-sim {cmd}: {msg}", file=sys.stderr)


def input_file(cmd: str, path) -> bool:
    """Whether the input `path` is a regular file (else one line said, for exit status 2)."""
    if not Path(path).is_file():
        _err(cmd, f"{path}: " + ("not a regular file" if os.path.exists(path) else "no such file"))
        return False
    return True


# --- recover ------------------------------------------------------------------------------------------
def cmd_recover(args) -> int:
    from gyro_sim.log.mcap_log import LogError
    from gyro_sim.log.recover import recover

    if not input_file("recover", args.log):
        return 2
    from gyro_sim.safe_paths import OutputError

    out = args.output or str(Path(args.log).with_suffix("")) + ".recovered.mcap"
    try:  # written under a temporary name, published when complete (recover.py)
        r = recover(args.log, out, overwrite=args.force)
    except (LogError, OutputError, OSError) as exc:
        _err("recover", exc)
        return 2
    try:  # done and published: a signal now does not change that
        print(r.report())
        print(f"wrote {out}")
    except KeyboardInterrupt:
        pass
    return 0


def register(sub, bench) -> None:
    """Add recover to the `gyro-sim` subparsers."""
    c = sub.add_parser("recover", help="rewrite a log cut short (SIGKILL, power loss) as a well-formed file")
    c.add_argument("log", help="the damaged MCAP file (not modified)")
    c.add_argument("-o", "--output", help="the recovered file (default: <log>.recovered.mcap)")
    c.add_argument("--force", action="store_true", help="replace an existing output file (never the input)")
    c.set_defaults(fn=cmd_recover)
