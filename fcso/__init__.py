"""FCSO: Fingerpad Customization with Set Operators (Lim & Pham).

Custom gripper fingerpads for 3D-printed parts, carved with Boolean set
operations so one pair of rigid fingers cages several parts in several
resting poses, ranked by contact area over the radius of the largest empty
sphere of contact normals.
"""

from .parallel import fork_safe_manifold  # noqa: E402
from .version import __version__

# before any Boolean of this process: workers are forked (fcso.parallel)
fork_safe_manifold()

from .config import DesignConfig, load_config  # noqa: E402
from .errors import (  # noqa: E402
    ComputeError,
    ConfigError,
    FcsoError,
    GeometryError,
    MeshError,
    NoGraspError,
    RepairToleranceError,
)
from .measure import quality_words  # noqa: E402
from .output.files import output_files, write_outputs, write_set_outputs  # noqa: E402
from .parts import MeshItem, Part, load_part, load_parts, read_3mf_items  # noqa: E402
from .pipeline import DesignResult, design  # noqa: E402
from .poses import stable_poses  # noqa: E402
from .reuse import KeptScenario, PadFit, fit_pads  # noqa: E402
from .rles import rles  # noqa: E402
from .sets import SetsResult, design_sets  # noqa: E402

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
