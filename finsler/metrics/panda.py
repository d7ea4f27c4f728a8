"""Franka Panda forward kinematics as CasADi SX expressions, and the pole metric of eq. (60).

The kinematic model comes from Pinocchio, which parses the Panda URDF shipped by the installed
``example-robot-data`` package (the URDF is never copied into this repository). The PyPI
Pinocchio wheels have no CasADi bindings, so the forward kinematics is rebuilt here in CasADi
from Pinocchio's model data: joint placements, joint axes, parent indices and frame placements.
``tests/finsler/metrics/test_panda_kinematics.py`` checks it against ``pinocchio.forwardKinematics`` +
``pinocchio.updateFramePlacements``.

Only the 7 arm joints are configuration coordinates: the finger joints of the URDF are locked at
the neutral configuration (``pinocchio.buildReducedModel``).
"""

from __future__ import annotations

import functools
import importlib.metadata
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import casadi
import numpy as np

from finsler.errors import InputError
from finsler.lowering import LoweredFunction, lower

if TYPE_CHECKING:  # imported in load_panda_model: the joint limits (the metric's domain,
    import pinocchio  # `geodesics metrics`) need no Pinocchio

__all__ = [
    "ARM_JOINT_NAMES",
    "FRAME_NAMES",
    "JOINT_LIMITS_HIGH",
    "JOINT_LIMITS_LOW",
    "NQ",
    "frame_positions_function",
    "frame_positions_sx",
    "load_panda_model",
    "lowered_frame_positions",
    "model_frame_positions_sx",
    "pole_metric_sx",
]

NQ = 7
"""Number of configuration coordinates (arm joints) of the reduced Panda model."""

ARM_JOINT_NAMES: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, NQ + 1))
"""The 7 actuated arm joints, in configuration order; every other joint is locked."""

FRAME_NAMES: tuple[str, ...] = (
    *(f"panda_link{i}" for i in range(9)),
    "panda_hand",
)
"""The 10 frames whose positions p_0(q), ..., p_9(q) enter eq. (60)."""

JOINT_LIMITS_LOW = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
"""Lower joint limits (rad), shape (7,); equal to the URDF's ``lowerPositionLimit``."""

JOINT_LIMITS_HIGH = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
"""Upper joint limits (rad), shape (7,); equal to the URDF's ``upperPositionLimit``."""

_URDF_SUFFIX = ("robots", "panda_description", "urdf", "panda.urdf")
_DISTRIBUTION = "example-robot-data"

# Rotation entries within this distance of 0, 1 or -1 are snapped to the exact value, so that
# CasADi drops multiplications by 0 and 1 (Pinocchio stores cos(pi/2) as 2.2e-16, not 0). The
# resulting change of the frame positions is of order 1e-16 m.
_SNAP_TOL = 1e-12

_AXIS_ALIGNED_REVOLUTE = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2}
_UNALIGNED_REVOLUTE = "JointModelRevoluteUnaligned"

# A rotation is stored as its 3 columns, each a (3, 1) SX.
_Columns = list[casadi.SX]


def _panda_urdf_path() -> Path:
    """Locate ``panda.urdf`` among the files installed by the ``example-robot-data`` package."""
    hint = f"install it into this environment (pip install {_DISTRIBUTION})"
    try:
        dist = importlib.metadata.distribution(_DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError as err:
        raise RuntimeError(f"the '{_DISTRIBUTION}' package is not installed; {hint}") from err
    files = dist.files or []
    for file in files:
        if tuple(file.parts[-len(_URDF_SUFFIX) :]) == _URDF_SUFFIX:
            path = Path(str(dist.locate_file(file)))
            if path.is_file():
                return path
            raise RuntimeError(
                f"'{_DISTRIBUTION}' lists the Panda URDF at {path}, but the file is missing; "
                f"reinstall the package"
            )
    raise RuntimeError(
        f"no file ending in {'/'.join(_URDF_SUFFIX)} among the {len(files)} files of the "
        f"installed '{_DISTRIBUTION}' {dist.version}; {hint}"
    )


@functools.lru_cache(maxsize=1)
def load_panda_model() -> pinocchio.Model:
    """Return the Pinocchio model of the 7-joint Panda arm (finger joints locked).

    The URDF is the one shipped by the installed ``example-robot-data`` package. Every joint that
    is not one of ``ARM_JOINT_NAMES`` (the two finger joints) is locked at the neutral
    configuration with ``pinocchio.buildReducedModel``, so ``model.nq == 7``. The result is
    cached and shared between callers: do not modify it.

    Raises:
        RuntimeError: if the package or its Panda URDF cannot be found, or if the model does not
            have the expected joints and frames.
    """
    import pinocchio

    full = pinocchio.buildModelFromUrdf(str(_panda_urdf_path()))
    missing = [name for name in ARM_JOINT_NAMES if not full.existJointName(name)]
    if missing:
        raise RuntimeError(f"the Panda URDF has no joints named {missing}")
    to_lock = [j for j in range(1, full.njoints) if full.names[j] not in ARM_JOINT_NAMES]
    if to_lock:
        model = pinocchio.buildReducedModel(full, to_lock, pinocchio.neutral(full))
    else:
        model = full
    if model.nq != NQ or tuple(model.names[1:]) != ARM_JOINT_NAMES:
        raise RuntimeError(
            f"reduced Panda model has nq={model.nq} and joints {list(model.names[1:])}; "
            f"expected the {NQ} joints {list(ARM_JOINT_NAMES)}"
        )
    missing = [name for name in FRAME_NAMES if not model.existFrame(name)]
    if missing:
        raise RuntimeError(f"the Panda model has no frames named {missing}")
    return model


def _snap(values: np.ndarray) -> np.ndarray:
    """Copy of ``values`` with entries within ``_SNAP_TOL`` of 0, 1 or -1 set exactly."""
    out = np.array(values, dtype=float)
    for target in (0.0, 1.0, -1.0):
        out[np.abs(out - target) < _SNAP_TOL] = target
    return out


def _combine(columns: _Columns, coefficients: np.ndarray) -> casadi.SX:
    """``sum_k coefficients[k] * columns[k]`` for constant coefficients, skipping zeros and ones.

    Args:
        columns: 3 symbolic columns, each (3, 1).
        coefficients: constant coefficients, shape (3,).

    Returns:
        (3, 1) SX.
    """
    total = None
    for column, coefficient in zip(columns, coefficients, strict=True):
        if coefficient == 0.0:
            continue
        if coefficient == 1.0:
            term = column
        elif coefficient == -1.0:
            term = -column
        else:
            term = coefficient * column
        total = term if total is None else total + term
    return casadi.SX.zeros(3, 1) if total is None else total


def _rotate_about_axis(columns: _Columns, axis: np.ndarray, angle: casadi.SX) -> _Columns:
    """Columns of ``R @ Rot(axis, angle)`` given the columns of ``R``.

    An axis equal to a coordinate axis uses the plain rotation matrix (two columns change);
    any other unit axis uses Rodrigues' formula ``I + sin K + (1 - cos) K^2``.

    Args:
        columns: columns of R, 3 SX of shape (3, 1).
        axis: constant axis, shape (3,).
        angle: scalar SX.

    Returns:
        The 3 columns of the rotated frame, each (3, 1).
    """
    cos, sin = casadi.cos(angle), casadi.sin(angle)
    axis = _snap(axis / np.linalg.norm(axis))
    if np.count_nonzero(axis) == 1 and axis.sum() == 1.0:
        k = int(np.flatnonzero(axis)[0])
        i, j = (k + 1) % 3, (k + 2) % 3  # Rot(e_k) maps e_i -> c e_i + s e_j, e_j -> -s e_i + c e_j
        rotated = list(columns)
        rotated[i] = cos * columns[i] + sin * columns[j]
        rotated[j] = cos * columns[j] - sin * columns[i]
        return rotated
    x, y, z = axis
    skew = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    skew2 = _snap(skew @ skew)
    rk = [_combine(columns, skew[:, m]) for m in range(3)]  # columns of R K
    rk2 = [_combine(columns, skew2[:, m]) for m in range(3)]  # columns of R K^2
    one_minus_cos = 1 - cos
    return [columns[m] + sin * rk[m] + one_minus_cos * rk2[m] for m in range(3)]


def _frame_parent_joint(frame: pinocchio.Frame) -> int:
    """Index of the joint a frame is attached to (``parentJoint``, or ``parent`` before 3.0)."""
    parent = getattr(frame, "parentJoint", None)
    return int(frame.parent if parent is None else parent)


def model_frame_positions_sx(
    model: pinocchio.Model, frame_names: Sequence[str], q: casadi.SX
) -> casadi.SX:
    """World positions of frames of a Pinocchio model, as an SX expression of the configuration.

    Supports models whose joints are all 1-dof revolute joints (``JointModelRX/RY/RZ`` and
    ``JointModelRevoluteUnaligned``). Transforms are composed along the kinematic tree from
    ``model.jointPlacements``, ``model.parents`` and each frame's parent joint and placement.

    Args:
        model: Pinocchio model with ``model.nq`` revolute joints.
        frame_names: names of the frames, length n.
        q: configuration, SX vector with ``model.nq`` entries.

    Returns:
        (n, 3) SX; row f is the world position of frame ``frame_names[f]``.

    Raises:
        TypeError: if q is not a casadi.SX.
        InputError: if q has the wrong size or a frame does not exist.
        NotImplementedError: if the model has a joint of another type.
    """
    if not isinstance(q, casadi.SX):
        raise TypeError(f"q must be a casadi.SX, got {type(q).__name__}")
    if not q.is_vector() or q.numel() != model.nq:
        raise InputError(f"q must be a vector with {model.nq} entries, got shape {q.shape}")
    q = casadi.vec(q)
    missing = [name for name in frame_names if not model.existFrame(name)]
    if missing:
        raise InputError(f"model has no frames named {missing}")

    identity = np.eye(3)
    rotations: list[_Columns] = [[casadi.SX(identity[:, m]) for m in range(3)]]
    translations: list[casadi.SX] = [casadi.SX.zeros(3, 1)]
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind = joint.shortname()
        if kind in _AXIS_ALIGNED_REVOLUTE:
            axis = identity[_AXIS_ALIGNED_REVOLUTE[kind]]
        elif kind == _UNALIGNED_REVOLUTE:
            axis = np.asarray(joint.extract().axis, dtype=float)
        else:
            raise NotImplementedError(f"joint {model.names[j]!r} of type {kind} is not supported")
        parent = model.parents[j]
        placement = model.jointPlacements[j]
        rotation = _snap(placement.rotation)
        rotations_parent = rotations[parent]
        columns = [_combine(rotations_parent, rotation[:, m]) for m in range(3)]
        translation = translations[parent] + _combine(
            rotations_parent, _snap(placement.translation)
        )
        rotations.append(_rotate_about_axis(columns, axis, q[joint.idx_q]))
        translations.append(translation)

    rows = []
    for name in frame_names:
        frame = model.frames[model.getFrameId(name)]
        j = _frame_parent_joint(frame)
        rows.append(translations[j] + _combine(rotations[j], _snap(frame.placement.translation)))
    return casadi.cse(casadi.horzcat(*rows).T)  # merge repeated subexpressions


def frame_positions_sx(q: casadi.SX) -> casadi.SX:
    """World positions of the Panda frames ``FRAME_NAMES`` as an SX expression of q.

    Args:
        q: joint angles (rad), SX vector with 7 entries.

    Returns:
        (10, 3) SX; row i is p_i(q) of eq. (60), the position (m) of ``FRAME_NAMES[i]`` in the
        base frame (panda_link0 is the origin).
    """
    return model_frame_positions_sx(load_panda_model(), FRAME_NAMES, q)


@functools.lru_cache(maxsize=1)
def frame_positions_function() -> casadi.Function:
    """Cached ``casadi.Function('panda_fk', [q], [P])``: q of shape (7, 1) -> P of shape (10, 3).

    See ``frame_positions_sx``.
    """
    q = casadi.SX.sym("q", NQ)
    return casadi.Function("panda_fk", [q], [frame_positions_sx(q)], ["q"], ["P"])


@functools.lru_cache(maxsize=1)
def lowered_frame_positions() -> LoweredFunction:
    """Cached lowered program of ``frame_positions_function`` (numpy or torch, batch-first):
    q ``(N, 7)`` -> ``(N, 30)``, each row the (10, 3) positions flattened column-major (as
    CasADi stores them). One per process, like the model: it does not depend on a metric's
    parameters."""
    return lower(frame_positions_function())


def pole_metric_sx(q: casadi.SX, v: casadi.SX, pole: tuple[float, float] = (0.4, 0.0)) -> casadi.SX:
    """Pole-avoiding Finsler (Riemannian, conformal) metric of eq. (60) for the Panda arm.

    ``F(q, v) = (1 + sum_{i=0}^{9} ((p_i(q)_x - o_x)^2 + (p_i(q)_y - o_y)^2)^(-1/2)) * ||v||``,
    with p_i the positions of ``FRAME_NAMES`` (``frame_positions_sx``), (o_x, o_y) = ``pole`` the
    position of a vertical pole obstacle and ||v|| the Euclidean norm. Domain: q in the joint
    limit box; F is infinite where a frame lies on the pole's axis.

    Args:
        q: joint angles (rad), SX vector with 7 entries.
        v: tangent vector, SX vector with 7 entries.
        pole: (o_x, o_y) in metres, finite.

    Returns:
        (1, 1) SX.

    Raises:
        TypeError: if v is not a casadi.SX.
        InputError: if v has the wrong size, the pole is not two finite numbers, or the pole lies
            on the axis of a frame that does not move (panda_link0, panda_link1).
    """
    if not isinstance(v, casadi.SX):
        raise TypeError(f"v must be a casadi.SX, got {type(v).__name__}")
    if not v.is_vector() or v.numel() != NQ:
        raise InputError(f"v must be a vector with {NQ} entries, got shape {v.shape}")
    pole_xy = np.asarray(pole, dtype=float)
    if pole_xy.shape != (2,) or not np.all(np.isfinite(pole_xy)):
        raise InputError(f"pole must be two finite numbers (o_x, o_y), got {pole!r}")
    positions = frame_positions_sx(q)
    squared = (positions[:, 0] - pole_xy[0]) ** 2 + (positions[:, 1] - pole_xy[1]) ** 2
    for i in range(squared.numel()):
        if squared[i].is_zero():
            raise InputError(f"the pole {tuple(pole_xy)} lies on the fixed frame {FRAME_NAMES[i]}")
    weight = 1 + casadi.sum1(1 / casadi.sqrt(squared))
    return weight * casadi.norm_2(casadi.vec(v))
