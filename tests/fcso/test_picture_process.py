"""The picture process: the same pictures as drawn in-process, its failures raised in the command."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time

import pytest

from fcso import design, load_part
from fcso.output.design_page import pictures, report_inputs
from fcso.output.picture_process import PictureProcess, PictureProcessError
from tests.conftest import HANG_GUARD_S, REPO, data_path, process_running, small_config


@pytest.fixture(scope="module")
def cube_inputs():
    result = design([load_part(data_path("20mm-xyz-cube.stl"))], small_config(search={"jobs": 2}))
    return report_inputs(result)


def test_the_process_draws_the_pictures_drawn_here(cube_inputs):
    steps = []
    with PictureProcess() as draw:
        drawn = draw(cube_inputs, lambda stage, done, total: steps.append((stage, done, total)))
    here = pictures(cube_inputs)
    assert (
        sorted(drawn)
        == sorted(here)
        == sorted(["gripper", "finger", "fingerpad", "grasp 0", "normals 0", "pose 0", "capture 0"])
    )
    assert all(drawn[name] == here[name] for name in here)
    assert steps == [("pictures", 0, 7), ("pictures", 7, 7)]


def test_a_failure_in_the_process_is_raised_in_the_command_and_the_process_serves_on(cube_inputs):
    without_grasps = dataclasses.replace(cube_inputs, grasps=[])
    with PictureProcess() as draw:
        with pytest.raises(IndexError):
            draw(without_grasps)
        assert draw(cube_inputs)["pose 0"].startswith(b"\x89PNG")


def test_a_killed_process_is_reported_with_its_exit_code(cube_inputs):
    draw = PictureProcess()
    os.kill(draw._process.pid, signal.SIGKILL)
    draw._process.join()
    with pytest.raises(PictureProcessError, match="exit code -9"):
        draw(cube_inputs)
    draw.close()
    assert not draw._process.is_alive()


def test_the_command_line_does_not_load_matplotlib_itself():
    loaded = subprocess.run(
        [sys.executable, "-c", "import sys, fcso.cli; print('matplotlib' in sys.modules)"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    )
    assert loaded.stdout.strip() == "False"


def test_workers_and_the_picture_process_die_with_a_killed_command(tmp_path):
    # a process that opens a worker pool and a picture process, reports their pids, then waits to be killed
    program = tmp_path / "holder.py"
    program.write_text(
        "import os, sys, time\n"
        "from fcso.parallel import WorkerPool\n"
        "from fcso.output.picture_process import PictureProcess\n"
        "pictures = PictureProcess()\n"
        "pool = WorkerPool(None, 2).__enter__()\n"
        "children = [p.pid for p in pool._pool._processes.values()] + [pictures._process.pid]\n"
        "print(' '.join(map(str, children)), flush=True)\n"
        "time.sleep(600)\n"
    )
    holder = subprocess.Popen([sys.executable, str(program)], cwd=REPO, stdout=subprocess.PIPE, text=True)
    children = [int(pid) for pid in holder.stdout.readline().split()]
    assert len(children) == 3
    holder.kill()
    holder.wait()
    deadline = time.monotonic() + HANG_GUARD_S
    while time.monotonic() < deadline and any(process_running(pid) for pid in children):
        time.sleep(0.1)
    assert not any(process_running(pid) for pid in children)
