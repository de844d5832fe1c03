"""`make demo`: the paper's experiment on the bundled Stanford bunny.

Runs ``fcso design`` exactly as a user would and leaves the outputs in
``demo-out/paper`` (finger.stl, fingerpad.stl, report.json).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "demo-out"


def main() -> int:
    command = [
        sys.executable, "-m", "fcso.cli", "design", str(REPO / "examples" / "parts" / "stanford_bunny_closed.ply"),
        "--scale-to", "65", "--config", str(REPO / "examples" / "paper.toml"), "--out", str(OUT / "paper"),
    ]
    print("$ fcso design examples/parts/stanford_bunny_closed.ply --scale-to 65 --config examples/paper.toml --out demo-out/paper")
    print("The paper's experiment (METHOD §10): bunny at 65 mm, Hand-E 50 mm, L = W = 20, T = 5, D = 4, poses 1 and 3.\n", flush=True)
    return subprocess.call(command)


if __name__ == "__main__":
    sys.exit(main())
