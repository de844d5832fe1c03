"""Holding: the largest push at the centre of mass a grasp resists (METHOD §7b).

The contact set of both pads resists a force ``F d`` at the part's centre of
mass, plus the part's weight, with Coulomb friction ``μ`` at every contact
and the gripper's grip: the two fingers are coupled (a parallel gripper
moves them symmetrically), so together they press with ``2 G`` along the
closing axis while the part cannot push one in and the other out. That is
a grasp wrench space question, answered by one linear programme per push
direction: the contact forces lie in friction cones (eight edges), balance
the push, the weight and every torque about the centre of mass, and press
with the grip; the largest ``F`` up to the test's force is the holding.

Contact far from the centre of mass lowers it: a push then turns the part
about the contact patch, and only friction spread over the patch resists.
"""

from __future__ import annotations

import numpy as np

#: Edges of each linearised friction cone.
CONE_EDGES = 8
#: Contacts are merged on a grid of this size (mm) per pad and normal direction: the
#: programme's size then follows the patch, not the sampling density.
MERGE_MM = 1.5
GRAVITY_M_S2 = 9.81


def push_directions(closing_axis: np.ndarray) -> np.ndarray:
    """The holding test's six pushes: ``±`` the sliding axis, the closing axis and the vertical (gripper frame axes)."""
    a = np.asarray(closing_axis, dtype=float)
    b = np.cross([0.0, 0.0, 1.0], a)
    return np.array([b, -b, a, -a, [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])


def merge_contacts(
    points: np.ndarray, normals: np.ndarray, pads: np.ndarray, merge_mm: float = MERGE_MM
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge contact samples per pad, grid cell and normal direction (mean point, mean normal).

    Parameters
    ----------
    points, normals : (n, 3) float
        Contact points (mm) and unit normals pointing into the part.
    pads : (n,) int
        Which finger each contact is on (0 or 1).

    Returns
    -------
    points, normals, pads of the merged contacts.
    """
    if len(points) == 0:
        return points, normals, pads
    cells = np.floor(points / merge_mm).astype(np.int64)
    # normals to the nearest of the 26 grid directions, so a patch's edges stay apart
    directions = np.rint(normals * 1.5).astype(np.int64)
    group = row_groups(np.column_stack([pads, cells, directions]))
    count = np.bincount(group)
    merged_points = np.column_stack([np.bincount(group, points[:, k]) for k in range(3)]) / count[:, None]
    merged_normals = np.column_stack([np.bincount(group, normals[:, k]) for k in range(3)])
    merged_normals /= np.maximum(np.linalg.norm(merged_normals, axis=1, keepdims=True), 1e-12)
    merged_pads = np.zeros(len(count), dtype=np.int64)
    merged_pads[group] = pads
    return merged_points, merged_normals, merged_pads


def row_groups(keys: np.ndarray) -> np.ndarray:
    """Each row's rank among the distinct rows of ``keys`` in lexicographic order: ``np.unique(keys, axis=0,
    return_inverse=True)[1]``, on one integer per row.

    The rows are numbered in mixed radix (each column less its least value, times the ranges of the columns after
    it), which orders them as the rows do; ``np.unique`` on rows sorts them as records, several times slower (a
    fifth of the screening's holding). Columns whose ranges overflow 62 bits go to ``np.unique`` on rows.

    Parameters
    ----------
    keys : (n, k) int64

    Returns
    -------
    (n,) int64
    """
    keys = np.asarray(keys, dtype=np.int64)
    if len(keys) == 0:
        return np.zeros(0, dtype=np.int64)
    low = keys.min(axis=0)
    spans = (keys.max(axis=0) - low + 1).astype(object)
    if np.prod(spans) >= 2**62:  # python integers: no overflow in the check itself
        return np.unique(keys, axis=0, return_inverse=True)[1].ravel().astype(np.int64)
    code = np.zeros(len(keys), dtype=np.int64)
    for column, span in zip((keys - low).T, spans):
        code = code * int(span) + column
    return np.unique(code, return_inverse=True)[1].ravel().astype(np.int64)


def holding_forces_n(
    points: np.ndarray,
    normals: np.ndarray,
    pads: np.ndarray,
    closing_axis: np.ndarray,
    centre_of_mass: np.ndarray,
    mass_kg: float,
    friction: float,
    grip_force_n: float,
    hold_force_n: float,
) -> np.ndarray:
    """The largest push at the centre of mass resisted in each of the six test directions.

    Parameters
    ----------
    points : (n, 3) float
        Contact points, mm (any frame with z up).
    normals : (n, 3) float
        Unit contact normals pointing into the part (the direction a pad pushes it).
    pads : (n,) int
        0 for the pad on the ``+closing_axis`` side (it pushes along ``-closing_axis``), 1 for the other.
    closing_axis : (3,) float
        Unit horizontal closing axis ``a``.
    centre_of_mass : (3,) float
        mm.
    mass_kg : float
    friction : float
        Coulomb coefficient μ.
    grip_force_n : float
        Each finger's grip force G, N.
    hold_force_n : float
        The test's largest push: the result is capped there, N.

    Returns
    -------
    (6,) float
        N, in the order of :func:`push_directions`; 0 where the contacts
        cannot even hold the part still against the grip and its weight.
    """
    directions = push_directions(closing_axis)
    points, normals, pads = merge_contacts(np.asarray(points, float), np.asarray(normals, float), np.asarray(pads))
    if len(points) == 0 or not (pads == 0).any() or not (pads == 1).any():
        return np.zeros(len(directions))
    edges = _cone_edges(normals, friction)  # (n, k, 3)
    count = len(points) * CONE_EDGES
    forces = edges.reshape(count, 3).T  # (3, n k)
    arms = np.repeat((points - centre_of_mass) / 1000.0, CONE_EDGES, axis=0)  # m
    torques = np.cross(arms, forces.T).T  # (3, n k)
    a = np.asarray(closing_axis, dtype=float)
    squeeze = np.where(np.repeat(pads, CONE_EDGES) == 0, -1.0, 1.0) * (a @ forces)
    weight = np.array([0.0, 0.0, -mass_kg * GRAVITY_M_S2])
    rhs = np.concatenate([-weight, np.zeros(3), [2.0 * grip_force_n]])
    return _largest_pushes(np.vstack([forces, torques, squeeze]), rhs, directions, hold_force_n)


def _largest_pushes(balance: np.ndarray, rhs: np.ndarray, directions: np.ndarray, hold_force_n: float) -> np.ndarray:
    """The largest push ``F`` along each direction that cone-edge magnitudes ``x >= 0`` balance, N.

    One linear programme (HiGHS) per direction: maximise ``F`` in ``[0, hold_force_n]`` subject to
    ``balance x + (direction, 0, 0, 0, 0) F = rhs``. The six differ only in ``F``'s column, so one model is
    solved six times with that column changed: each solve starts from the last basis (simplex warm start),
    without the model being built again.

    Parameters
    ----------
    balance : (7, m) float
        Force (N), torque (N m) and squeeze rows of every cone edge.
    rhs : (7,) float
    directions : (k, 3) float
        Unit push directions.
    hold_force_n : float

    Returns
    -------
    (k,) float
        N; 0 where no ``F >= 0`` balances (the contacts cannot hold the part still).
    """
    import highspy  # the LP solver loads when a holding force is first computed, not with the method

    count = balance.shape[1]
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = count + 1, len(rhs)
    lp.col_cost_ = np.r_[np.zeros(count), -1.0]
    lp.col_lower_ = np.zeros(count + 1)
    lp.col_upper_ = np.r_[np.full(count, highspy.kHighsInf), hold_force_n]
    lp.row_lower_ = lp.row_upper_ = np.asarray(rhs, dtype=np.float64)
    # column-wise, F's column holding its three force rows (changed per direction)
    full = np.hstack([balance, np.zeros((len(rhs), 1))])
    full[:3, count] = 1.0
    rows, columns = np.nonzero(full.T)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = np.r_[0, np.cumsum(np.bincount(rows, minlength=count + 1))].astype(np.int32)
    lp.a_matrix_.index_ = columns.astype(np.int32)
    lp.a_matrix_.value_ = full.T[rows, columns]
    solver = highspy.Highs()
    # no log, and no thread pool: fcso's parallelism is its worker processes, forked from this one
    solver.setOptionValue("output_flag", False)
    solver.setOptionValue("threads", 1)
    # seven rows: presolve finds nothing to remove and would discard the warm basis (20 % of the time)
    solver.setOptionValue("presolve", "off")
    solver.passModel(lp)
    results = []
    for direction in directions:
        for row in range(3):
            solver.changeCoeff(row, count, float(direction[row]))
        solver.run()
        optimal = solver.getModelStatus() == highspy.HighsModelStatus.kOptimal
        # F is the only cost: the objective is -F (the solution vector is thousands of values, copied into a list);
        # 0 - (-0.0) is 0.0, so no -0.0 reaches a report
        results.append(0.0 - solver.getInfo().objective_function_value if optimal else 0.0)
    return np.array(results)


def _cone_edges(normals: np.ndarray, friction: float) -> np.ndarray:
    """Unit-normal-component edges ``n + μ t_k`` of each contact's linearised friction cone, (n, k, 3)."""
    helper = np.where(np.abs(normals[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    first = np.cross(normals, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    second = np.cross(normals, first)
    angles = 2.0 * np.pi * np.arange(CONE_EDGES) / CONE_EDGES
    tangents = np.cos(angles)[None, :, None] * first[:, None, :] + np.sin(angles)[None, :, None] * second[:, None, :]
    return normals[:, None, :] + friction * tangents
