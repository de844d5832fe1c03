"""Draw the README's picture: both designed fingers closed on the part of a design's first grasp.

Usage: ``python docs/images/readme_picture.py DIR OUT.png`` where DIR is an
output folder of ``fcso design`` (report.json, finger.stl, fingerpad.stl).
"""

from __future__ import annotations

import sys
from pathlib import Path

from fcso.output.design_page import load_report_inputs
from fcso.output.pictures import gripper_picture


def main(directory: str, target: str) -> None:
    inputs = load_report_inputs(directory)
    settings = inputs.report.settings.sampler
    first = inputs.grasps[0]
    scenario = inputs.report.scenarios[0]
    title = f"{scenario.part} (pose {scenario.pose_index}) in the designed fingers"
    png = gripper_picture(
        first.mesh,
        inputs.finger,
        inputs.pad_to_finger,
        first.placements,
        (settings.thickness_mm, settings.length_mm, settings.width_mm),
        first.sample.closing_axis,
        title,
    )
    Path(target).write_bytes(png)
    print(target)


if __name__ == "__main__":
    main(*sys.argv[1:3])
