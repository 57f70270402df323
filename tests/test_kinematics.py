"""sim/robot.py and sim/kinematics.py: pytorch-kinematics agrees with pybullet, IK solves and refuses, frames map."""

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import pybullet as p
import pytest
import torch
from pytorch_kinematics.transforms import rotation_conversions as rc

from sim.kinematics import ArmKinematics, IKConfig, root_to_world, world_to_root, wxyz_to_xyzw, xyzw_to_wxyz
from sim.robot import (ARM_JOINTS, FACING_PLUS_X, HAND_PARENT_LINK, RobotConfig, icub_urdf_path, load_icub,
                       quiet_c_output)

# A base pose that is neither the origin nor axis-aligned, so root->world mapping is exercised for real.
BASE_POS = (0.3, -0.2, 0.65)
BASE_QUAT = tuple(p.getQuaternionFromEuler((0.0, 0.0, 2.0)))


@pytest.fixture(scope="module")
def world():
    client = p.connect(p.DIRECT)
    robot = load_icub(client, BASE_POS, BASE_QUAT)
    yield client, robot
    p.disconnect(client)


@pytest.fixture(scope="module")
def kin():
    return ArmKinematics()


def random_q(kin, n, seed):
    g = torch.Generator().manual_seed(seed)
    return kin.lower + torch.rand(n, len(ARM_JOINTS), generator=g, dtype=torch.float64) * (kin.upper - kin.lower)


def angle_between(qa_wxyz, qb_wxyz):
    d = rc.quaternion_multiply(qa_wxyz, rc.quaternion_invert(qb_wxyz))
    return 2.0 * torch.atan2(d[..., 1:].norm(dim=-1), d[..., 0].abs())


# ------------------------------------------------------------------------------------------------ robot loading

def test_urdf_cache_resolves_meshes_outside_the_repo():
    path = icub_urdf_path()
    assert path == icub_urdf_path()  # cached: same file, same name
    assert Path(__file__).resolve().parents[1] not in path.resolve().parents
    meshes = [m.get("filename") for m in ET.parse(path).getroot().iter("mesh")]
    assert meshes and not any(m.startswith("package://") for m in meshes)
    assert all(Path(m).is_file() for m in set(meshes))


def test_load_is_silent_and_maps_the_arm(capfd, world):
    client = p.connect(p.DIRECT)
    robot = load_icub(client)
    out, err = capfd.readouterr()
    assert "b3Warning" not in out + err and "merge" not in out + err
    assert [p.getJointInfo(robot.body, j, physicsClientId=client)[1].decode() for j in robot.arm_joints] == list(
        ARM_JOINTS)
    assert p.getJointInfo(robot.body, robot.hand_link, physicsClientId=client)[12].decode() == HAND_PARENT_LINK
    # frozen body: only the arm chain moves
    movable = [i for i in range(p.getNumJoints(robot.body, physicsClientId=client))
               if p.getJointInfo(robot.body, i, physicsClientId=client)[2] != p.JOINT_FIXED]
    assert sorted(movable) == sorted(robot.arm_joints)
    # limits are the URDF's (r_elbow: 15 to 106 degrees)
    i = ARM_JOINTS.index("r_elbow")
    assert robot.lower[i] == pytest.approx(math.radians(15.0), abs=1e-6)
    assert robot.upper[i] == pytest.approx(1.8500490071139892)
    # phantom masses gone: the forearm weighs its URDF 0.6347 kg, not +1 kg per merged skin patch
    forearm = robot.link_index["r_forearm"]
    assert p.getDynamicsInfo(robot.body, forearm, physicsClientId=client)[0] == pytest.approx(0.6347, abs=0.01)
    p.disconnect(client)


def test_set_arm_round_trip_and_limits(world, kin):
    _, robot = world
    q = random_q(kin, 1, seed=3)[0]
    robot.set_arm(q)
    assert torch.allclose(robot.arm_q(), q, atol=1e-9)
    bad = robot.home().clone()
    bad[ARM_JOINTS.index("r_elbow")] = 0.0  # below the elbow's 15 degree lower limit
    with pytest.raises(ValueError, match="r_elbow"):
        robot.set_arm(bad)
    with pytest.raises(ValueError, match="10 joint values"):
        robot.drive_arm(torch.zeros(7))


def test_motors_reach_target_under_gravity_and_body_holds():
    """drive_arm moves the arm where asked and keeps it there; an unfrozen body is held by its motors."""
    client = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    cfg = RobotConfig(freeze_body=False)
    robot = load_icub(client, (0, 0, 0.6), config=cfg)
    target = robot.home() + torch.tensor([0.1, 0.1, 0.1, -0.3, 0.2, 0.2, -0.3, 0.3, -0.2, 0.1], dtype=torch.float64)
    robot.drive_arm(target)
    for _ in range(480):  # 2 s at 240 Hz: 0.3 rad at 1 rad/s plus settling
        p.stepSimulation(physicsClientId=client)
    assert (robot.arm_q() - target).abs().max() < 1e-3
    posture = dict(cfg.body_posture)
    for name, j in robot.joint_index.items():
        if name not in ARM_JOINTS:
            q = p.getJointState(robot.body, j, physicsClientId=client)[0]
            assert q == pytest.approx(posture.get(name, 0.0), abs=0.02), name
    p.disconnect(client)


# ------------------------------------------------------------------------------------------------ FK vs pybullet

def test_fk_matches_pybullet_link_state(world, kin):
    """pk's palm pose, mapped to world by the base pose, equals pybullet's (1 mm, 1 degree), for random q."""
    client, robot = world
    wrist = ArmKinematics(end_link=HAND_PARENT_LINK)
    q = random_q(kin, 25, seed=1)
    pos, quat = kin.fk(q)
    wpos, wquat = root_to_world(pos, quat, BASE_POS, BASE_QUAT)
    rpos, rquat = root_to_world(*wrist.fk(q), BASE_POS, BASE_QUAT)
    for i in range(len(q)):
        robot.set_arm(q[i])
        hp, hq = robot.hand_pose()
        assert (hp - wpos[i]).norm() < 1e-3
        assert angle_between(xyzw_to_wxyz(hq), wquat[i]) < math.radians(1.0)
        # the moving link itself (no palm offset involved): pybullet's link frame, not its inertial frame
        s = p.getLinkState(robot.body, robot.hand_link, computeForwardKinematics=True, physicsClientId=client)
        assert (torch.tensor(s[4], dtype=torch.float64) - rpos[i]).norm() < 1e-3
        assert angle_between(xyzw_to_wxyz(torch.tensor(s[5], dtype=torch.float64)), rquat[i]) < math.radians(1.0)


def test_root_frame_conventions(kin):
    """root_link: x backward, y to the robot's right, z up; the home palm is in front of the pelvis."""
    frames = kin.fk_frames(kin.home[None])
    shoulder = frames["r_shoulder_1"][0, :3, 3]
    assert shoulder[1] > 0.1 and shoulder[2] > 0.1  # right shoulder: to the right, above the pelvis
    palm = frames["r_hand_dh_frame"][0, :3, 3]
    assert palm[0] < -0.1  # in front
    # torso_yaw turns the chest about the vertical: the shoulder's height does not change
    q = kin.home.clone()
    q[ARM_JOINTS.index("torso_yaw")] = 0.5
    turned = kin.fk_frames(q[None])["r_shoulder_1"][0, :3, 3]
    assert turned[2] == pytest.approx(shoulder[2].item(), abs=1e-9)
    assert (turned[:2] - shoulder[:2]).norm() > 0.04


def test_frame_maps_by_hand():
    """Yaw +90 degrees and a shift: root x -> world y, and back."""
    base_q = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
    w, wq = root_to_world(torch.tensor([[1.0, 0.0, 0.0]], dtype=torch.float64),
                          torch.tensor([[1.0, 0.0, 0.0, 0.0]], dtype=torch.float64), (1.0, 2.0, 3.0), base_q)
    assert torch.allclose(w, torch.tensor([[1.0, 3.0, 3.0]], dtype=torch.float64), atol=1e-12)
    assert torch.allclose(wxyz_to_xyzw(wq), torch.tensor([base_q], dtype=torch.float64), atol=1e-12)
    r, rq = world_to_root(w, wq, (1.0, 2.0, 3.0), base_q)
    assert torch.allclose(r, torch.tensor([[1.0, 0.0, 0.0]], dtype=torch.float64), atol=1e-12)
    assert angle_between(rq, torch.tensor([[1.0, 0.0, 0.0, 0.0]], dtype=torch.float64)) < 1e-9
    # FACING_PLUS_X: the robot's front (root -x) is world +x
    front, _ = root_to_world(torch.tensor([[-1.0, 0.0, 0.0]], dtype=torch.float64), None, (0, 0, 0), FACING_PLUS_X)
    assert torch.allclose(front, torch.tensor([[1.0, 0.0, 0.0]], dtype=torch.float64), atol=1e-12)


# ------------------------------------------------------------------------------------------------ IK

def test_ik_round_trip_position(kin):
    """FK of random q -> IK from home -> FK again lands on the target, inside the limits."""
    q_true = random_q(kin, 40, seed=2)
    target, _ = kin.fk(q_true)
    res = kin.ik(target)
    assert res.success.all()
    pos, _ = kin.fk(res.q)
    assert ((pos - target).norm(dim=1) < kin.config.pos_tol).all()
    assert torch.allclose(res.pos_err, (pos - target).norm(dim=1), atol=1e-9)
    assert ((res.q >= kin.lower) & (res.q <= kin.upper)).all()


def test_ik_round_trip_full_pose_from_other_start(kin):
    q_true = random_q(kin, 20, seed=4)
    target, quat = kin.fk(q_true)
    start = random_q(kin, 20, seed=5)
    res = kin.ik(target, quat, q0=start)
    assert res.success.all()
    pos, got = kin.fk(res.q)
    assert ((pos - target).norm(dim=1) < kin.config.pos_tol).all()
    assert (angle_between(got, quat) < kin.config.rot_tol).all()


def test_ik_palm_down(kin):
    """target_normal constrains only the palm's +z axis: it ends pointing down, spin left free."""
    target = torch.tensor([[-0.30, 0.15, 0.0], [-0.25, 0.05, 0.10]], dtype=torch.float64)
    res = kin.ik(target, target_normal=torch.tensor([[0.0, 0.0, -1.0]]).expand(2, 3))
    assert res.success.all()
    z = kin.fk_matrix(res.q)[:, :3, 2]
    assert (z[:, 2] < -math.cos(kin.config.rot_tol)).all()


def test_unreachable_and_reachable(kin):
    """Far targets fail with the error of the distance beyond the reach; a point the hand has been at succeeds."""
    far = torch.tensor([[-2.0, 0.0, 0.0], [0.0, 0.0, 3.0]], dtype=torch.float64)
    res = kin.ik(far)
    assert not res.success.any()
    assert (res.pos_err > 1.0).all()  # the arm spans well under 1 m from the pelvis
    been_at, _ = kin.fk(random_q(kin, 3, seed=6))
    ok = kin.reachable(torch.cat([far, been_at]))
    assert ok.tolist() == [False, False, True, True, True]
    assert ((res.q >= kin.lower) & (res.q <= kin.upper)).all()  # failed answers stay inside the limits too


def test_reach_tolerance_at_the_edge(kin):
    """A target 5 mm past the closest point the palm gets to (along the failed direction) is within 1 cm only."""
    far = torch.tensor([[-2.0, 0.1, 0.1]], dtype=torch.float64)
    edge_q = kin.ik(far).q
    edge, _ = kin.fk(edge_q)
    beyond = edge + 0.005 * (far - edge) / (far - edge).norm()
    assert kin.reachable(beyond, tol=0.01).item()
    assert not kin.reachable(beyond, tol=0.001).item()


def test_ik_deterministic_and_batch_independent(kin):
    targets = torch.tensor([[-0.3, 0.1, 0.0], [-0.6, 0.5, 0.4], [-0.2, 0.3, 0.2]], dtype=torch.float64)
    a = kin.ik(targets, generator=torch.Generator().manual_seed(7))
    b = kin.ik(targets, generator=torch.Generator().manual_seed(7))
    assert torch.equal(a.q, b.q) and torch.equal(a.success, b.success)
    # the restarts are shared by all targets: a target's answer does not depend on its batch-mates
    for i in range(len(targets)):
        alone = kin.ik(targets[i:i + 1], generator=torch.Generator().manual_seed(7))
        assert alone.success.item() == a.success[i].item()
        assert torch.allclose(alone.q[0], a.q[i], atol=1e-9)


def test_float32_and_bad_input():
    kin32 = ArmKinematics(dtype=torch.float32, config=IKConfig(restarts=2))
    target, _ = kin32.fk(kin32.home[None] + 0.2)
    assert target.dtype == torch.float32 and kin32.ik(target).success.all()
    with pytest.raises(ValueError, match="target_pos"):
        kin32.ik(torch.zeros(3))
    with pytest.raises(ValueError, match="not both"):
        kin32.ik(target, torch.tensor([[1.0, 0, 0, 0]]), target_normal=torch.tensor([[0, 0, -1.0]]))
    with pytest.raises(ValueError, match="target_normal"):
        kin32.ik(target, target_normal=torch.zeros(1, 3))
    with pytest.raises(ValueError, match="q0"):
        kin32.ik(target, q0=torch.zeros(2, 10))
    with pytest.raises(ValueError, match="q"):
        kin32.fk(torch.zeros(4, 9))


def test_quiet_c_output_restores_fds(capfd):
    with quiet_c_output():
        pass
    print("visible")
    assert "visible" in capfd.readouterr().out


def test_load_refuses_bad_posture():
    with pytest.raises(ValueError, match="r_elbow"):
        load_icub(-1, config=RobotConfig(body_posture=(("r_elbow", 1.0),)))  # an arm joint: IK's, not posture's
    with pytest.raises(ValueError, match="l_elbow"):
        load_icub(-1, config=RobotConfig(body_posture=(("l_elbow", 0.0),)))  # below its 15 degree limit
    with pytest.raises(ValueError, match="base_position"):
        load_icub(-1, base_position=(0.0, 0.0))


def test_the_simulator_leaves_pytorch_kinematics_whole_and_matplotlib_out():
    """sim.kinematics loads only pytorch-kinematics' chain and rotations (its package __init__ pulls in matplotlib)
    and not scipy (arm_pytorch_utilities' linalg, loaded when first used); both packages are still whole for
    whoever imports them after: the same module objects, pk's IK solver and the linalg functions there."""
    import subprocess
    import sys
    code = ("import sys, sim.world, sim.kinematics as k; assert 'matplotlib' not in sys.modules; "
            "assert 'scipy' not in sys.modules, 'scipy imported'; "
            "import torch, arm_pytorch_utilities as apu; from arm_pytorch_utilities import linalg; "
            "x = torch.ones(2, 3, 3); assert torch.equal(linalg.batch_batch_product(torch.ones(2, 3), x), "
            "torch.full((2, 3), 3.0)); assert apu.cov is linalg.cov and 'scipy.linalg' in sys.modules; "
            "import pytorch_kinematics as pk; from pytorch_kinematics import SerialChain; "
            "assert pk.PseudoInverseIK and pk.transforms.Transform3d and SerialChain; "
            "assert pk.build_serial_chain_from_urdf is k.build_serial_chain_from_urdf and pk.chain.SerialChain is "
            "SerialChain; assert 'matplotlib' in sys.modules; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-2000:]
