"""Outcomes of simulated grasps and holding pushes, cached under the hash of everything that determines them.

MuJoCo is deterministic: the same model, start state, controller and
settings give the same trajectory to the last bit. So an outcome (a
grasp's final pose in the gripper, whether it held, its frames and the
state after its lift; a push's slip force) is stored under the hash of all
of it, and a verification that ran before (a daemon killed or restarted
during it, a job printed again, a finger reused for the same parts) reads
it instead of simulating it again. The key holds

- the scene's model source (:attr:`fcso.sim.scene.Scene.model_sha256`:
  every collision piece, mass, contact setting, the time step, friction
  and gripper);
- the grasp case (TCP, the part's vertices, the pads' size and gap, the
  gripper's opening) and the part's start pose;
- every ``[verify]`` setting that changes a simulation (not those that
  judge, count or schedule them: :data:`NOT_SIMULATED`);
- the code that drives the gripper (the source of :mod:`fcso.sim.trials`),
  the versions of MuJoCo, NumPy and SciPy, the processor's architecture
  (MuJoCo's arithmetic may differ on another; a cache folder may be shared)
  and :data:`OUTCOME_VERSION`.

A push starts from its grasp's state after the lift, so its key is its
grasp's key and its direction. Entries live in the collision pieces' cache
folder (:mod:`fcso.sim.diskcache`: written whole, bounded in size).
"""

from __future__ import annotations

import hashlib
import io
import json
import platform
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import scipy

from . import trials
from .config import VerifyConfig
from .diskcache import read_entry, write_entry
from .scene import GraspCase, Scene
from .trials import Frame

#: Bumped when what an entry holds, or how it is keyed, changes.
OUTCOME_VERSION = "outcome-1"
#: ``[verify]`` settings that judge, count or schedule the simulations without changing any of them.
NOT_SIMULATED = frozenset(
    {
        "trials",
        "success_mm",
        "success_deg",
        "pass_success_rate",
        "stop_early",
        "hold_tolerance_n",
        "max_seated_penetration_mm",
        "choice_budget_s",
        # a simulation runs the same in any arena it fits in (one it does not fit in fails, and is not stored)
        "arena_mb",
        "arena_retry_factor",
        "jobs",
        "cache_dir",
        "reuse_simulations",
    }
)
#: MuJoCo's state that a simulation continues from (positions, velocities, controls, applied forces, the solver's
#: warm start): set with the model's derived quantities recomputed, it continues bit for bit.
STATE = mujoco.mjtState.mjSTATE_INTEGRATION


@dataclass
class TrialRun:
    """What a grasp returns from its worker: held, final pose in the gripper (4x4, mm), its frames when recorded, a
    nominal grasp's state after the lift (:func:`saved_state`), and whether it was read from the cache."""

    held: bool
    part_in_gripper: np.ndarray
    frames: list[Frame] | None
    lifted: np.ndarray | None = None
    reused: bool = False


def saved_state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """The state a simulation continues from (:data:`STATE`), as a flat array."""
    state = np.empty(mujoco.mj_stateSize(model, STATE))
    mujoco.mj_getState(model, data, state, STATE)
    return state


def restored_state(model: mujoco.MjModel, state: np.ndarray) -> mujoco.MjData:
    """A simulation set to ``state`` (:func:`saved_state`), its derived quantities computed: it continues bit for bit
    as the one the state was taken from."""
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, np.asarray(state, dtype=np.float64), STATE)
    mujoco.mj_forward(model, data)
    return data


def scene_key(scene: Scene, case: GraspCase, config: VerifyConfig) -> str:
    """Hash (hex sha256) of what every simulation of ``scene`` shares: model, case, settings and code."""
    digest = hashlib.sha256(OUTCOME_VERSION.encode())
    versions = (mujoco.__version__, np.__version__, scipy.__version__, platform.machine())
    for text in (*versions, Path(trials.__file__).read_text(), scene.model_sha256):
        digest.update(text.encode())
        digest.update(b"\0")
    for values in (
        case.tcp,
        case.part.vertices,
        case.pad_size_mm,
        [case.pad_gap_mm],
        case.opening_mm,
        [scene.pad_inset_mm],
    ):
        digest.update(np.ascontiguousarray(values, dtype="<f8").tobytes())
    settings = config.model_dump(mode="json", exclude=set(NOT_SIMULATED))
    digest.update(json.dumps(settings, sort_keys=True).encode())
    return digest.hexdigest()


def grasp_key(scene_key_hex: str, part_pose: np.ndarray, record: bool) -> str:
    """Hash of one grasp of a scene: the part's start pose (4x4, mm) and whether its frames are kept."""
    digest = hashlib.sha256(scene_key_hex.encode())
    digest.update(np.ascontiguousarray(part_pose, dtype="<f8").tobytes())
    digest.update(b"record" if record else b"")
    return digest.hexdigest()


def hold_key(grasp_key_hex: str, direction: str) -> str:
    """Hash of one holding push from a grasp's state after the lift."""
    return hashlib.sha256(f"{grasp_key_hex} hold {direction}".encode()).hexdigest()


def reuse_or_simulate_grasp(
    cache_dir: Path, key: str, reuse: bool, model: mujoco.MjModel, simulate: Callable[[], TrialRun]
) -> TrialRun:
    """The grasp's outcome from the cache when ``reuse`` and it is there, else ``simulate()`` (then stored).

    Parameters
    ----------
    cache_dir : Path
    key : str
        :func:`grasp_key`.
    reuse : bool
    model : mujoco.MjModel
        The scene's model (a stored state after the lift must fit it).
    simulate : callable
        Runs the grasp.
    """
    stored = _read(cache_dir / f"{key}.npz") if reuse else None
    if stored is not None and (run := _grasp_from(stored, model)) is not None:
        return run
    run = simulate()
    write_entry(cache_dir / f"{key}.npz", _grasp_entry(run))
    return run


def reuse_or_simulate_hold(
    cache_dir: Path, key: str, reuse: bool, simulate: Callable[[], float | None]
) -> tuple[float | None, bool]:
    """A holding push's slip force (N; None: held) from the cache when ``reuse`` and it is there, else
    ``simulate()`` (then stored); and whether it came from the cache.

    Parameters
    ----------
    cache_dir : Path
    key : str
        :func:`hold_key`.
    reuse : bool
    simulate : callable
        Runs the push.
    """
    stored = _read(cache_dir / f"{key}.npz") if reuse else None
    if stored is not None and "force_n" in stored:
        force = float(stored["force_n"][0])
        return (None if np.isnan(force) else force), True
    force = simulate()
    write_entry(cache_dir / f"{key}.npz", _entry(force_n=np.array([np.nan if force is None else force])))
    return force, False


def _read(path: Path) -> dict[str, np.ndarray] | None:
    data = read_entry(path)
    if data is None:
        return None
    try:
        with np.load(io.BytesIO(data)) as stored:
            return {name: stored[name] for name in stored.files}
    except (OSError, ValueError, zipfile.BadZipFile):
        # damaged: simulated again and written over
        return None


def _entry(**arrays: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def _grasp_entry(run: TrialRun) -> bytes:
    frames = run.frames or []
    arrays = {
        "held": np.array([run.held]),
        "part_in_gripper": np.asarray(run.part_in_gripper, dtype=float),
        "recorded": np.array([run.frames is not None]),
        "frame_times_s": np.array([f.time_s for f in frames], dtype=float),
        "frame_parts": np.array([f.part for f in frames], dtype=float).reshape(-1, 4, 4),
        "frame_grippers": np.array([f.gripper for f in frames], dtype=float).reshape(-1, 4, 4),
        "frame_openings_mm": np.array([f.q_mm for f in frames], dtype=float),
    }
    if run.lifted is not None:
        arrays["state_after_lift"] = run.lifted
    return _entry(**arrays)


def _grasp_from(stored: dict[str, np.ndarray], model: mujoco.MjModel) -> TrialRun | None:
    try:
        frames = [
            Frame(float(t), part, gripper, float(q))
            for t, part, gripper, q in zip(
                stored["frame_times_s"], stored["frame_parts"], stored["frame_grippers"], stored["frame_openings_mm"]
            )
        ]
        lifted = stored.get("state_after_lift")
        if lifted is not None and len(lifted) != mujoco.mj_stateSize(model, STATE):
            return None
        return TrialRun(
            held=bool(stored["held"][0]),
            part_in_gripper=np.asarray(stored["part_in_gripper"], dtype=float),
            frames=frames if bool(stored["recorded"][0]) else None,
            lifted=lifted,
            reused=True,
        )
    except KeyError:
        return None
