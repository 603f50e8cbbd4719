"""The serial chain: positions and Jacobians against finite differences, the planar arm against
eq. 1's closed form, compiled against numpy, the presets against their published geometry and
pinocchio, and the URDF loader against pinocchio's own frames."""

import importlib.metadata

import numpy as np
import pytest

from qpbench.exceptions import InputError
from qpbench.robot.chain import (
    chain_data,
    compiled_chain,
    forward_kinematics_np,
    make_model,
    planar_chain,
    points_jacobians_np,
)
from qpbench.robot.kinematics import Arm, PlanarArm, default_key_points
from qpbench.robot.presets import chain_from_urdf, iiwa14, make_chain, panda


def skewed_chain(n=5, seed=4):
    """A spatial chain of random placements and random (unaligned) unit axes."""
    rng = np.random.default_rng(seed)
    rot = np.linalg.qr(rng.normal(size=(n + 1, 3, 3)))[0]
    rot *= np.sign(np.linalg.det(rot))[:, None, None]  # proper rotations
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    t = rng.uniform(-0.3, 0.3, (n + 1, 3))
    return make_model(rot[:-1], t[:-1], axis, rot[-1], t[-1], 3, q_min=-2.0, q_max=2.0)


CHAINS = {
    "planar4": lambda: planar_chain([0.3, 0.4, 0.15, 0.15]),
    "planar7": lambda: planar_chain(np.linspace(0.1, 0.3, 7)),
    "panda": panda,
    "iiwa14": iiwa14,
    "skewed": skewed_chain,
}


def random_q(model, rng):
    lo = np.where(np.isfinite(model.q_min), model.q_min, -np.pi)
    hi = np.where(np.isfinite(model.q_max), model.q_max, np.pi)
    return rng.uniform(lo, hi)


def random_points(model, rng, a=6):
    links = np.append(rng.integers(0, model.n, a), model.n - 1)
    return links, np.append(rng.uniform(0, 1, a), 1.0)


@pytest.mark.parametrize("name", CHAINS)
def test_jacobians_are_the_finite_differences_of_the_positions(name):
    model, rng, h = CHAINS[name](), np.random.default_rng(7), 1e-6
    for _ in range(5):
        q = random_q(model, rng)
        links, fracs = random_points(model, rng)
        x, J = points_jacobians_np(model, q, links, fracs)
        fd = np.empty_like(J)
        for k in range(model.n):
            e = np.zeros(model.n)
            e[k] = h
            xp = points_jacobians_np(model, q + e, links, fracs)[0]
            xm = points_jacobians_np(model, q - e, links, fracs)[0]
            fd[:, :, k] = ((xp - xm) / (2 * h))[:, : model.dim]
        np.testing.assert_allclose(J, fd, atol=1e-7)
        if model.dim == 2:  # the plane z = 0
            assert np.all(x[:, 2] == 0)


@pytest.mark.parametrize("name", CHAINS)
def test_rotations_are_proper_and_axes_follow_them(name):
    model, rng = CHAINS[name](), np.random.default_rng(3)
    data = forward_kinematics_np(model, random_q(model, rng))
    R = data.rotation
    np.testing.assert_allclose(
        R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-13
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-13)
    np.testing.assert_allclose(np.einsum("kij,kj->ki", R[:-1], model.axis), data.axis, atol=1e-13)


def old_planar(lengths, theta, links, fracs):
    """Eq. 1 and 7b as the planar arm had them: complex exponentials of the absolute angles."""
    z = np.concatenate([[0], np.cumsum(lengths * np.exp(1j * np.cumsum(theta)))])
    x = z[links] + fracs * (z[links + 1] - z[links])
    rel = x[:, None] - z[None, :-1]
    mask = np.arange(len(lengths))[None, :] <= links[:, None]
    J = np.stack([-rel.imag * mask, rel.real * mask], axis=1)
    return z, np.stack([x.real, x.imag], axis=1), J


def test_planar_chain_equals_eq_1():
    rng = np.random.default_rng(11)
    for n in (2, 4, 9):
        lengths = rng.uniform(0.05, 0.5, n)
        arm = PlanarArm(lengths)
        theta = rng.uniform(-np.pi, np.pi, (3, n))  # a batch
        z = np.array([old_planar(lengths, t, np.array([0]), np.array([0.0]))[0] for t in theta])
        p = arm.joint_positions(theta)
        assert p.shape == (3, n + 1, 2)
        np.testing.assert_allclose(p, np.stack([z.real, z.imag], axis=-1), atol=1e-12)
        links, fracs = random_points(arm.model, rng)
        _, x_old, J_old = old_planar(lengths, theta[0], links, fracs)
        x, J = arm.points_jacobians(theta[0], links, fracs)
        np.testing.assert_allclose(x, x_old, atol=1e-12)
        np.testing.assert_allclose(arm.points(theta[0], links, fracs), x_old, atol=1e-12)
        np.testing.assert_allclose(J, J_old, atol=1e-12)
        np.testing.assert_allclose(arm.end_effector(theta)[1], p[1, -1], atol=0)
        np.testing.assert_allclose(arm.lengths, lengths, rtol=1e-15)


@pytest.mark.parametrize("name", CHAINS)
def test_compiled_equals_numpy(name):
    model, rng = CHAINS[name](), np.random.default_rng(5)
    cc, data = compiled_chain(), chain_data(model)
    links, fracs = random_points(model, rng)
    X, J = np.zeros((links.size, 3)), np.zeros((links.size, model.dim, model.n))
    for _ in range(3):
        q = random_q(model, rng)
        cc.points_jacobians(model, q, data, links, fracs, X, J)
        ref = forward_kinematics_np(model, q)
        for got, want in zip(data, ref):
            np.testing.assert_allclose(got, want, atol=1e-14)
        x_np, J_np = points_jacobians_np(model, q, links, fracs)
        np.testing.assert_allclose(X, x_np, atol=1e-14)
        np.testing.assert_allclose(J, J_np, atol=1e-14)
        x1, J1 = np.zeros(3), np.full((model.dim, model.n), np.nan)
        cc.link_point(data, links[0], fracs[0], x1)
        cc.point_jacobian(data, links[0], x1, J1)
        np.testing.assert_array_equal(x1, X[0])
        np.testing.assert_array_equal(J1, J[0])


def test_presets_zero_configuration_is_the_published_geometry():
    # Panda at q = 0: flange at x = a4 - a5 ... = 0.088, z = 0.333 + 0.316 + 0.384 - 0.107.
    np.testing.assert_allclose(
        Arm(panda()).end_effector(np.zeros(7)), [0.088, 0, 0.926], atol=1e-15
    )
    # iiwa 14 R820 upright: axes 2, 4, 6 at 360, 780, 1180 mm, the flange at 1306 mm.
    p = Arm(iiwa14()).joint_positions(np.zeros(7))
    np.testing.assert_allclose(
        p[[1, 3, 5, 7]], [[0, 0, z] for z in (0.36, 0.78, 1.18, 1.306)], atol=1e-15
    )
    for m, v_max in (
        (panda(), [2.175] * 4 + [2.61] * 3),
        (iiwa14(), np.radians([85, 85, 100, 75, 130, 135, 135])),
    ):
        np.testing.assert_allclose(m.v_max, v_max)
    np.testing.assert_allclose(np.degrees(iiwa14().q_max), [170, 120, 170, 120, 170, 120, 175])
    np.testing.assert_allclose(panda().q_max[3], -0.0698)


def test_spatial_key_points_skip_zero_length_links():
    model = panda()
    kp = default_key_points(model.n, 1, True, 0.05, lengths=model.lengths)
    assert 0 not in kp.links and 4 not in kp.links  # the two links of zero length
    x = Arm(model).points(np.random.default_rng(0).uniform(-1, 1, 7), kp.links, kp.fracs)
    gaps = np.linalg.norm(x[:, None] - x[None], axis=-1) + np.eye(len(kp))
    assert gaps.min() > 0.03  # no point twice


def test_make_chain_kinds_and_errors(tmp_path):
    np.testing.assert_array_equal(make_chain("panda", radius=0.06).radius, np.full(7, 0.06))
    assert make_chain("planar", link_lengths=[0.3, 0.4]).dim == 2
    with pytest.raises(InputError, match="did you mean 'panda'"):
        make_chain("pandas")
    with pytest.raises(InputError, match="robot.v_mx"):
        make_chain("iiwa14", v_mx=1.0)
    with pytest.raises(InputError, match="q_min < q_max"):
        make_chain("panda", q_min=3.0)
    with pytest.raises(InputError, match="robot.link_lengths"):
        make_chain("planar", link_lengths=[0.3, -0.4])
    with pytest.raises(InputError, match="robot.ee_frame"):
        make_chain("urdf", file=str(tmp_path / "arm.urdf"))


# --- URDF through pinocchio ---

LINK = '<link name="{0}"/>'
JOINT = (
    '<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
    '<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>'
    '<limit lower="{lo}" upper="{hi}" effort="10" velocity="{vel}"/></joint>'
)


def write_urdf(path, joints):
    """A URDF of a chain of ``joints`` (name, kind, xyz, rpy, axis, lo, hi, velocity) from
    link ``base``, each joint's child named ``<joint>_link``; a finger branches off the last."""
    links, parent, body = ["base"], "base", []
    for name, kind, xyz, rpy, axis, lo, hi, vel in joints:
        child = f"{name}_link"
        body.append(JOINT.format(name=name, kind=kind, parent=parent, child=child, xyz=xyz,
                                 rpy=rpy, axis=axis, lo=lo, hi=hi, vel=vel))  # fmt: skip
        links.append(child)
        parent = child
    body.append(JOINT.format(name="finger", kind="prismatic", parent=parent, child="finger_link",
                             xyz="0 0.02 0.05", rpy="0 0 0", axis="0 1 0", lo=0, hi=0.04, vel=0.2))  # fmt: skip
    links.append("finger_link")
    text = "".join(LINK.format(n) for n in links) + "".join(body)
    path.write_text(f'<?xml version="1.0"?><robot name="arm">{text}</robot>')
    return path


# The iiwa 14 R820 as its URDF describes it, a fixed flange joint at the end.
IIWA_URDF = [
    ("a1", "revolute", "0 0 0.1575", "0 0 0", "0 0 1", -2.96706, 2.96706, 1.48353),
    ("a2", "revolute", "0 0 0.2025", "1.5707963267948966 0 3.141592653589793", "0 0 1", -2.0944, 2.0944, 1.48353),
    ("a3", "revolute", "0 0.2045 0", "1.5707963267948966 0 3.141592653589793", "0 0 1", -2.96706, 2.96706, 1.74533),
    ("a4", "revolute", "0 0 0.2155", "1.5707963267948966 0 0", "0 0 1", -2.0944, 2.0944, 1.309),
    ("a5", "revolute", "0 0.1845 0", "-1.5707963267948966 3.141592653589793 0", "0 0 1", -2.96706, 2.96706, 2.26893),
    ("a6", "revolute", "0 0 0.2155", "1.5707963267948966 0 0", "0 0 1", -2.0944, 2.0944, 2.35619),
    ("a7", "revolute", "0 0.081 0", "-1.5707963267948966 3.141592653589793 0", "0 0 1", -3.05433, 3.05433, 2.35619),
    ("flange", "fixed", "0 0 0.045", "0 0 0", "0 0 1", 0, 0, 0),
]  # fmt: skip
# A small arm with unaligned and negative axes and a fixed joint between two revolute ones.
ODD_URDF = [
    ("j1", "revolute", "0.1 0 0.2", "0.3 -0.2 0.5", "0 0 -1", -2, 2, 1),
    ("bracket", "fixed", "0 0.05 0.1", "0.1 0 0", "1 0 0", 0, 0, 0),
    ("j2", "revolute", "0.2 0 0", "0 0.4 0", "0.6 0 0.8", -1, 1.5, 2),
    ("j3", "revolute", "0 0.25 0.05", "-0.7 0 0.2", "0 1 0", -2.5, 0.5, 3),
    ("tool", "fixed", "0.03 0.01 0.12", "0 0.2 0", "0 0 1", 0, 0, 0),
]


def pin_frame(urdf, frame, q):
    """Pinocchio's placement and world-aligned Jacobian (3 x nv) of ``frame`` at ``q``."""
    pin = pytest.importorskip("pinocchio")
    model = pin.buildModelFromUrdf(str(urdf))
    data, fid = model.createData(), model.getFrameId(frame)
    qf = pin.neutral(model)
    qf[: q.size] = q
    pin.framesForwardKinematics(model, data, qf)
    pin.computeJointJacobians(model, data, qf)
    J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3, : q.size]
    return data.oMf[fid].translation, J, [data.oMi[j].translation for j in range(1, q.size + 1)]


@pytest.mark.parametrize("joints, frame", [(IIWA_URDF, "flange_link"), (ODD_URDF, "tool_link")])
def test_urdf_chain_equals_pinocchios_frame(tmp_path, joints, frame):
    pytest.importorskip("pinocchio")
    urdf = write_urdf(tmp_path / "arm.urdf", joints)
    model = chain_from_urdf(urdf, frame)
    revolute = [j for j in joints if j[1] == "revolute"]
    assert model.n == len(revolute)
    np.testing.assert_allclose(model.v_max, [j[7] for j in revolute])
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = random_q(model, rng)
        x_pin, J_pin, joints_pin = pin_frame(urdf, frame, q)
        x, J = points_jacobians_np(model, q, [model.n - 1], [1.0])
        np.testing.assert_allclose(x[0], x_pin, atol=1e-12)
        np.testing.assert_allclose(J[0], J_pin, atol=1e-12)
        np.testing.assert_allclose(
            forward_kinematics_np(model, q).position[:-1], joints_pin, atol=1e-12
        )
        if joints is IIWA_URDF:  # the preset is this URDF
            x_pre, J_pre = points_jacobians_np(iiwa14(), q, [6], [1.0])
            np.testing.assert_allclose(x_pre, x, atol=1e-12)
            np.testing.assert_allclose(J_pre, J, atol=1e-12)


def test_urdf_refuses_what_is_not_a_revolute_chain(tmp_path):
    pytest.importorskip("pinocchio")
    urdf = write_urdf(tmp_path / "arm.urdf", ODD_URDF)
    with pytest.raises(InputError, match=r"arm.urdf.*joint 'finger' is prismatic"):
        chain_from_urdf(urdf, "finger_link")
    spun = [(*j[:1], "continuous", *j[2:]) if j[0] == "j2" else j for j in ODD_URDF]
    with pytest.raises(InputError, match=r"joint 'j2' is continuous \(no limits\)"):
        chain_from_urdf(write_urdf(tmp_path / "spun.urdf", spun), "tool_link")
    with pytest.raises(InputError, match=r"did you mean 'tool_link'"):
        chain_from_urdf(urdf, "tool_lnk")


def panda_urdf():
    """The Panda URDF example-robot-data ships, if installed (an optional check: 131 MB)."""
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    want = "panda_description/urdf/panda.urdf"
    return next(f.locate() for f in files if str(f).endswith(want))


def test_panda_preset_equals_the_shipped_urdf():
    pytest.importorskip("pinocchio")
    urdf, model, rng = panda_urdf(), panda(), np.random.default_rng(9)
    loaded = chain_from_urdf(urdf, "panda_link8")
    for field in ("q_min", "q_max", "v_max"):
        np.testing.assert_allclose(getattr(loaded, field), getattr(model, field), atol=1e-12)
    for _ in range(10):
        q = random_q(model, rng)
        x_pin, J_pin, joints_pin = pin_frame(urdf, "panda_link8", q)
        x, J = points_jacobians_np(model, q, [6], [1.0])
        np.testing.assert_allclose(x[0], x_pin, atol=1e-10)
        np.testing.assert_allclose(J[0], J_pin, atol=1e-10)
        np.testing.assert_allclose(
            forward_kinematics_np(model, q).position[:-1], joints_pin, atol=1e-10
        )


@pytest.mark.parametrize("scenario", ["wall", "panda_table", "iiwa_wall"])
def test_a_logs_positions_compiled_equal_numpys_forward_kinematics(scenario):
    """The body's clearance reads a run's joint positions compiled, row after row; numpy's
    batched forward kinematics is the reference."""
    from qpbench.robot.chain import forward_kinematics_np, positions_many
    from qpbench.sim.scenario import load_scenario

    sc = load_scenario(scenario)
    model = sc.make_controller().arm.model
    Q = sc.theta0 + 0.5 * np.random.default_rng(3).standard_normal((500, len(sc.theta0)))
    assert np.abs(positions_many(model, Q) - forward_kinematics_np(model, Q).position).max() < 1e-14
