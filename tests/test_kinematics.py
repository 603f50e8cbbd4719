"""Planar chain: forward kinematics, Jacobians (vs finite differences), key points."""

from __future__ import annotations

import numpy as np
import pytest

from qpbench.exceptions import InputError
from qpbench.robot.kinematics import PlanarArm, default_key_points


def fk_complex(lengths, theta, link, frac):
    """Independent forward kinematics with complex numbers: the point ``frac`` along ``link``."""
    z = 0j
    phi = 0.0
    for i in range(link + 1):
        phi += theta[i]
        step = lengths[i] * np.exp(1j * phi)
        z += frac * step if i == link else step
    return np.array([z.real, z.imag])


def fd_jacobian(lengths, theta, link, frac, h=1e-6):
    J = np.zeros((2, len(theta)))
    for k in range(len(theta)):
        e = np.zeros(len(theta))
        e[k] = h
        J[:, k] = (
            fk_complex(lengths, theta + e, link, frac) - fk_complex(lengths, theta - e, link, frac)
        ) / (2 * h)
    return J


@pytest.mark.parametrize("n", range(2, 9))
def test_jacobians_match_finite_differences(n):
    rng = np.random.default_rng(n)
    for _ in range(5):
        lengths = rng.uniform(0.05, 0.6, n)
        arm = PlanarArm(lengths)
        theta = rng.uniform(-np.pi, np.pi, n)
        links = rng.integers(0, n, 6)
        fracs = rng.uniform(0, 1, 6)
        x, J = arm.points_jacobians(theta, links, fracs)
        for j in range(6):
            np.testing.assert_allclose(
                x[j], fk_complex(lengths, theta, links[j], fracs[j]), atol=1e-12
            )
            np.testing.assert_allclose(
                J[j], fd_jacobian(lengths, theta, links[j], fracs[j]), atol=1e-8
            )
            # columns beyond the point's link are exactly zero
            assert np.all(J[j][:, links[j] + 1 :] == 0.0)
        np.testing.assert_allclose(
            arm.points_jacobians(theta, [n - 1], [1.0])[1][0],
            fd_jacobian(lengths, theta, n - 1, 1.0),
            atol=1e-8,
        )
        np.testing.assert_allclose(
            arm.end_effector(theta), fk_complex(lengths, theta, n - 1, 1.0), atol=1e-12
        )


def test_joint_positions_geometry():
    arm = PlanarArm([0.3, 0.4, 0.15, 0.15])
    np.testing.assert_allclose(arm.end_effector(np.zeros(4)), [1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(arm.end_effector([np.pi / 2, 0, 0, 0]), [0.0, 1.0], atol=1e-15)
    rng = np.random.default_rng(1)
    theta = rng.uniform(-3, 3, 4)
    p = arm.joint_positions(theta)
    np.testing.assert_allclose(np.linalg.norm(np.diff(p, axis=0), axis=1), arm.lengths)
    d = np.diff(p, axis=0)  # link i points along phi[i] = sum(theta[:i+1])
    np.testing.assert_allclose(
        np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - np.cumsum(theta)))), 0, atol=1e-12
    )


def test_paper_key_points():
    kp = default_key_points(4)
    # A1, A3, A5, A7 at link midpoints; A2, A4, A6 at joints J2, J3, J4
    assert kp.names == ("A1", "A2", "A3", "A4", "A5", "A6", "A7")
    np.testing.assert_array_equal(kp.links, [0, 0, 1, 1, 2, 2, 3])
    np.testing.assert_allclose(kp.fracs, [0.5, 1, 0.5, 1, 0.5, 1, 0.5])
    arm = PlanarArm([0.3, 0.4, 0.15, 0.15])
    theta = np.array([1.57, -0.628, -0.524, -0.524])
    p = arm.joint_positions(theta)
    x = arm.points(theta, kp.links, kp.fracs)
    np.testing.assert_allclose(x[[1, 3, 5]], p[1:4], atol=1e-15)
    np.testing.assert_allclose(x[[0, 2, 4, 6]], 0.5 * (p[:4] + p[1:]), atol=1e-15)
    # the end effector is never a key point
    assert not np.any(np.all(np.isclose(x, p[4]), axis=1))


def test_configurable_key_points():
    kp = default_key_points(3, points_per_link=3, include_joints=False, radius=0.02)
    assert len(kp) == 9
    np.testing.assert_allclose(kp.fracs[:3], [0.25, 0.5, 0.75])
    assert kp.radius == 0.02
    with pytest.raises(InputError):
        default_key_points(3, points_per_link=0, include_joints=False)


@pytest.mark.parametrize("lengths", [[0.3], [0.3, 0.0], [0.3, -0.1], [0.3, np.nan]])
def test_bad_lengths_rejected(lengths):
    with pytest.raises(InputError) as err:
        PlanarArm(lengths)
    assert "link_lengths" in str(err.value)
