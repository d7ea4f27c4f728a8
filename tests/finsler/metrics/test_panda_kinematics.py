"""Panda forward kinematics in CasADi (finsler.metrics.panda) against Pinocchio's own algorithms."""

from __future__ import annotations

import casadi
import numpy as np
import pinocchio
import pytest

from finsler.metrics.panda import (
    FRAME_NAMES,
    JOINT_LIMITS_HIGH,
    JOINT_LIMITS_LOW,
    frame_positions_function,
    frame_positions_sx,
    load_panda_model,
    model_frame_positions_sx,
    pole_metric_sx,
)

N_SAMPLES = 50


def _random_configurations(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 7) joint angles drawn uniformly in the joint limit box."""
    return rng.uniform(JOINT_LIMITS_LOW, JOINT_LIMITS_HIGH, size=(n, 7))


def _pinocchio_frame_positions(
    model: pinocchio.Model, frame_names: tuple[str, ...], q: np.ndarray
) -> np.ndarray:
    """(len(frame_names), 3) world frame positions by forwardKinematics + updateFramePlacements."""
    data = model.createData()
    pinocchio.forwardKinematics(model, data, q)
    pinocchio.updateFramePlacements(model, data)
    return np.array([data.oMf[model.getFrameId(name)].translation for name in frame_names])


def test_model_is_the_seven_joint_arm() -> None:
    model = load_panda_model()
    assert model.nq == 7
    assert model.nv == 7
    assert list(model.names[1:]) == [f"panda_joint{i}" for i in range(1, 8)]
    assert load_panda_model() is model  # cached


def test_joint_limits_match_model() -> None:
    model = load_panda_model()
    assert JOINT_LIMITS_LOW.shape == JOINT_LIMITS_HIGH.shape == (7,)
    np.testing.assert_allclose(JOINT_LIMITS_LOW, model.lowerPositionLimit, rtol=0, atol=1e-4)
    np.testing.assert_allclose(JOINT_LIMITS_HIGH, model.upperPositionLimit, rtol=0, atol=1e-4)
    assert np.all(JOINT_LIMITS_LOW < JOINT_LIMITS_HIGH)


def test_frame_names_are_ten_distinct_frames_with_link0_at_origin() -> None:
    model = load_panda_model()
    assert len(FRAME_NAMES) == 10
    assert FRAME_NAMES[0] == "panda_link0"
    assert FRAME_NAMES[-1] == "panda_hand"
    assert all(model.existFrame(name) for name in FRAME_NAMES)
    frame_ids = {model.getFrameId(name) for name in FRAME_NAMES}
    assert len(frame_ids) == 10

    f = frame_positions_function()
    for q in _random_configurations(np.random.default_rng(1), 5):
        np.testing.assert_array_equal(np.asarray(f(q))[0], np.zeros(3))
        np.testing.assert_array_equal(_pinocchio_frame_positions(model, FRAME_NAMES, q)[0], 0.0)


def test_fk_matches_pinocchio() -> None:
    model = load_panda_model()
    f = frame_positions_function()
    assert f.size_in(0) == (7, 1)
    assert f.size_out(0) == (10, 3)
    configurations = _random_configurations(np.random.default_rng(0), N_SAMPLES)
    batch = np.asarray(f.map(N_SAMPLES)(configurations.T))  # (10, 3 * N_SAMPLES)
    for k, q in enumerate(configurations):
        expected = _pinocchio_frame_positions(model, FRAME_NAMES, q)
        actual = np.asarray(f(q))
        assert actual.shape == (10, 3)
        np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-9)
        np.testing.assert_allclose(batch[:, 3 * k : 3 * k + 3], expected, rtol=0, atol=1e-9)


def test_fk_jacobian_matches_finite_differences_of_pinocchio() -> None:
    """IPOPT differentiates the SX kinematics: its exact Jacobian must match central
    differences of Pinocchio's own forward kinematics (an independent implementation)."""
    model = load_panda_model()
    q = casadi.SX.sym("q", 7)
    positions = frame_positions_sx(q)
    assert positions.shape == (10, 3)
    jac = casadi.Function("J", [q], [casadi.jacobian(casadi.vec(positions), q)])
    h = 1e-6
    for qv in _random_configurations(np.random.default_rng(2), 3):
        got = np.asarray(jac(qv))  # (30, 7), column-major vec of the (10, 3) positions
        want = np.empty_like(got)
        for j in range(7):
            e = np.zeros(7)
            e[j] = h
            dp = (_pinocchio_frame_positions(model, FRAME_NAMES, qv + e)
                  - _pinocchio_frame_positions(model, FRAME_NAMES, qv - e)) / (2 * h)
            want[:, j] = dp.reshape(-1, order="F")
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-7)


def test_pole_metric_matches_numpy_reference() -> None:
    model = load_panda_model()
    q, v = casadi.SX.sym("q", 7), casadi.SX.sym("v", 7)
    rng = np.random.default_rng(3)
    for pole in [(0.4, 0.0), (-0.3, 0.25)]:
        metric = casadi.Function("F", [q, v], [pole_metric_sx(q, v, pole=pole)])
        for qv in _random_configurations(rng, N_SAMPLES):
            vv = rng.normal(size=7) * rng.uniform(0.01, 10.0)
            p = _pinocchio_frame_positions(model, FRAME_NAMES, qv)
            inverse_distances = ((p[:, 0] - pole[0]) ** 2 + (p[:, 1] - pole[1]) ** 2) ** -0.5
            expected = (1.0 + inverse_distances.sum()) * np.linalg.norm(vv)
            actual = float(metric(qv, vv))
            assert actual == pytest.approx(expected, rel=1e-9, abs=0.0)


def test_pole_metric_default_pole_and_zero_velocity() -> None:
    q, v = casadi.SX.sym("q", 7), casadi.SX.sym("v", 7)
    default = casadi.Function("F", [q, v], [pole_metric_sx(q, v)])
    explicit = casadi.Function("F", [q, v], [pole_metric_sx(q, v, pole=(0.4, 0.0))])
    other = casadi.Function("F", [q, v], [pole_metric_sx(q, v, pole=(0.0, 0.4))])
    qv = _random_configurations(np.random.default_rng(4), 1)[0]
    vv = np.arange(1.0, 8.0)
    assert float(default(qv, vv)) == float(explicit(qv, vv))
    assert float(default(qv, vv)) != float(other(qv, vv))
    assert float(default(qv, np.zeros(7))) == 0.0


def test_bad_inputs_raise() -> None:
    q, v = casadi.SX.sym("q", 7), casadi.SX.sym("v", 7)
    with pytest.raises(ValueError, match="7 entries"):
        frame_positions_sx(casadi.SX.sym("q", 6))
    with pytest.raises(ValueError, match="7 entries"):
        pole_metric_sx(q, casadi.SX.sym("v", 3, 3))
    with pytest.raises(TypeError, match=r"casadi\.SX"):
        frame_positions_sx(casadi.MX.sym("q", 7))
    with pytest.raises(ValueError, match="finite"):
        pole_metric_sx(q, v, pole=(np.nan, 0.0))
    with pytest.raises(ValueError, match="panda_link0"):
        pole_metric_sx(q, v, pole=(0.0, 0.0))
    with pytest.raises(ValueError, match="no frames"):
        model_frame_positions_sx(load_panda_model(), ("no_such_frame",), q)


def test_generic_builder_on_other_revolute_joint_types() -> None:
    """RX, RY and unaligned revolute joints with arbitrary placements, against Pinocchio."""
    rng = np.random.default_rng(5)
    model = pinocchio.Model()
    joint_models = [
        pinocchio.JointModelRX(),
        pinocchio.JointModelRY(),
        pinocchio.JointModelRevoluteUnaligned(np.array([0.0, 0.6, 0.8])),
        pinocchio.JointModelRZ(),
        pinocchio.JointModelRevoluteUnaligned(np.array([-1.0, 2.0, 0.5]) / np.sqrt(5.25)),
    ]
    parents = [0, 1, 2, 2, 4]  # joint 4 branches off joint 2
    frame_names = []
    for k, (joint_model, parent) in enumerate(zip(joint_models, parents, strict=True)):
        joint_id = model.addJoint(parent, joint_model, pinocchio.SE3.Random(), f"j{k}")
        name = f"f{k}"
        model.addFrame(
            pinocchio.Frame(name, joint_id, pinocchio.SE3.Random(), pinocchio.FrameType.OP_FRAME)
        )
        frame_names.append(name)
    frame_names = tuple(frame_names)
    q = casadi.SX.sym("q", model.nq)
    f = casadi.Function("fk", [q], [model_frame_positions_sx(model, frame_names, q)])
    for qv in rng.uniform(-np.pi, np.pi, size=(20, model.nq)):
        expected = _pinocchio_frame_positions(model, frame_names, qv)
        np.testing.assert_allclose(np.asarray(f(qv)), expected, rtol=0, atol=1e-9)
