"""FCSO: Fingerpad Customization with Set Operators (Lim & Pham).

Custom gripper fingerpads for 3D-printed parts, carved with Boolean set
operations so one pair of rigid fingers cages several parts in several
resting poses, ranked by contact area over the radius of the largest empty
sphere of contact normals.

The public names below load their module when first used (PEP 562), so a
command that needs little of fcso (``fcso --help``, reading a report) does
not load the pipeline, its compiled kernels or the simulation.
"""

import importlib
from typing import TYPE_CHECKING

from .startup import collector_paused

with collector_paused():
    from .parallel import fork_safe_manifold
    from .version import __version__

    # before any Boolean of this process: workers are forked (fcso.parallel)
    fork_safe_manifold()

    from .errors import (
        ComputeError,
        ConfigError,
        FcsoError,
        GeometryError,
        MeshError,
        NoGraspError,
        RepairToleranceError,
    )

    # a module of the same name: importing it would otherwise bind fcso.rles to the module
    from .rles import rles

if TYPE_CHECKING:  # what the names below are, for type checkers and editors
    from .config import DesignConfig, load_config
    from .measure import quality_words
    from .output.files import output_files, write_outputs, write_set_outputs
    from .parts import Part, load_part, load_parts
    from .pipeline import DesignResult, design
    from .poses import stable_poses
    from .reuse import KeptScenario, PadFit, fit_pads
    from .sets import SetsResult, design_sets
    from .threemf import MeshItem, read_3mf_items

#: Public name -> the module that defines it, imported on first use.
_LAZY = {
    "DesignConfig": ".config",
    "load_config": ".config",
    "DesignResult": ".pipeline",
    "design": ".pipeline",
    "quality_words": ".measure",
    "output_files": ".output.files",
    "write_outputs": ".output.files",
    "write_set_outputs": ".output.files",
    "MeshItem": ".threemf",
    "Part": ".parts",
    "load_part": ".parts",
    "load_parts": ".parts",
    "read_3mf_items": ".threemf",
    "stable_poses": ".poses",
    "KeptScenario": ".reuse",
    "PadFit": ".reuse",
    "fit_pads": ".reuse",
    "SetsResult": ".sets",
    "design_sets": ".sets",
}


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "__version__",
    "ComputeError",
    "ConfigError",
    "DesignConfig",
    "DesignResult",
    "FcsoError",
    "GeometryError",
    "MeshError",
    "RepairToleranceError",
    "NoGraspError",
    "MeshItem",
    "Part",
    "design",
    "design_sets",
    "fit_pads",
    "KeptScenario",
    "PadFit",
    "SetsResult",
    "write_set_outputs",
    "load_config",
    "load_part",
    "load_parts",
    "read_3mf_items",
    "output_files",
    "write_outputs",
    "quality_words",
    "rles",
    "stable_poses",
]
