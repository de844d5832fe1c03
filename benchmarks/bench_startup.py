"""Start-up of the commands, as whole processes, against the import floor (trimesh, manifold3d and scipy).

Usage::

    python -m benchmarks.bench_startup [--runs N] [--against CHECKOUT] [--no-paper]

Runs ``fcso --help``, the operator commands ``fcsod jobs``, ``fcsod fingers
list`` and ``fcsod journal check`` (on a journal of one job) and the paper
command (``make paper``'s ``fcso design``), each as a fresh process, round
by round beside the floor ``python -c "import trimesh, manifold3d, scipy"``
(and with ``--against`` the same command of another checkout, its own
``.venv``), so that a slow spell of a shared machine slows every command of
a round alike. Prints each command's median wall time and its ratio to the
floor's median (the targets: 1.3x for the commands, 3x for the paper
command), and against the other checkout the median of the per-round
ratios. The first round is a warm-up (page cache, numba's on-disk cache)
and is not counted.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fcsod.service.journal import Journal

ROOT = Path(__file__).resolve().parents[1]

#: The ratio to the floor each command should stay within.
TARGETS = {"paper": 3.0}
DEFAULT_TARGET = 1.3

OPERATOR_CONFIG = """
[watch]
roots = ["watch"]

[output]
root = "out"

[state]
dir = "state"
"""


def commands(checkout: Path, config: Path, out: Path) -> dict[str, list[str]]:
    """Name -> argv of each command of ``checkout`` (its ``.venv``)."""
    bin_dir = checkout / ".venv" / "bin"
    fcsod = [str(bin_dir / "fcsod")]
    operator = ["--config", str(config)]
    return {
        "fcso --help": [str(bin_dir / "fcso"), "--help"],
        "fcsod jobs": [*fcsod, "jobs", *operator],
        "fcsod fingers list": [*fcsod, "fingers", "list", *operator],
        "fcsod journal check": [*fcsod, "journal", "check", *operator],
        "paper": [
            str(bin_dir / "fcso"),
            "design",
            str(checkout / "examples" / "parts" / "stanford_bunny_closed.ply"),
            "--scale-to",
            "65",
            "--config",
            str(checkout / "examples" / "paper.toml"),
            "--out",
            str(out / checkout.name),
        ],
    }


def wall_s(argv: list[str], cwd: Path) -> float:
    """Wall time of one run of ``argv``, s; raises when it fails."""
    started = time.perf_counter()
    subprocess.run(argv, cwd=cwd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    return time.perf_counter() - started


def operator_config(folder: Path) -> Path:
    """A daemon config whose journal holds one job (``fcsod jobs`` lists it)."""
    (folder / "state").mkdir()
    (folder / "watch").mkdir()
    config = folder / "fcsod.toml"
    config.write_text(OPERATOR_CONFIG)
    journal = Journal(folder / "state" / "journal.sqlite3")
    journal.add("job-1", str(folder / "watch" / "job"), "2026-01-01T00:00:00+00:00")
    journal.close()
    return config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="counted rounds")
    parser.add_argument("--against", type=Path, help="another checkout (with its .venv) to run beside this one")
    parser.add_argument("--no-paper", action="store_true", help="leave out the paper command")
    args = parser.parse_args()
    floor = [sys.executable, "-c", "import trimesh, manifold3d, scipy"]
    with tempfile.TemporaryDirectory() as folder:
        base = Path(folder)
        config = operator_config(base)
        checkouts = {"this": ROOT, **({"other": args.against.resolve()} if args.against else {})}
        runs = {name: commands(checkout, config, base) for name, checkout in checkouts.items()}
        names = [name for name in runs["this"] if not (args.no_paper and name == "paper")]
        times: dict[tuple[str, str], list[float]] = {}
        for number in range(args.runs + 1):
            for name in names:
                # the floor beside every command: its ratio is taken against its own round
                measured = {("floor", name): wall_s(floor, base)}
                for checkout in checkouts:
                    measured[(checkout, name)] = wall_s(runs[checkout][name], checkouts[checkout])
                if number > 0:
                    for key, seconds in measured.items():
                        times.setdefault(key, []).append(seconds)
    floor_s = statistics.median(t for name in names for t in times[("floor", name)])
    print(f"import floor (python -c 'import trimesh, manifold3d, scipy'): median {floor_s:.2f} s, {args.runs} rounds")
    header = f"{'command':<22} {'median s':>9} {'x floor':>8} {'target':>7}"
    if args.against:
        header += f" {'other s':>8} {'other x':>8} {'this/other':>11}"
    print(header)
    for name in names:
        mine = times[("this", name)]
        ratio = statistics.median(m / f for m, f in zip(mine, times[("floor", name)]))
        line = f"{name:<22} {statistics.median(mine):9.2f} {ratio:7.2f}x {TARGETS.get(name, DEFAULT_TARGET):6.1f}x"
        if args.against:
            other = times[("other", name)]
            other_ratio = statistics.median(o / f for o, f in zip(other, times[("floor", name)]))
            pairs = statistics.median(m / o for m, o in zip(mine, other))
            line += f" {statistics.median(other):8.2f} {other_ratio:7.2f}x {pairs:10.2f}x"
        print(line)


if __name__ == "__main__":
    main()
