"""LEO in MuJoCo (thesis 4.2.3) against the original robot model (GRL's leoconfig.xml) and Erik's task.

Expected values are computed here from the reference's quoted constants, not read back from the model.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sb3_er_envs.leo.leo", reason="LEO needs the dmc extra (dm_control, MuJoCo)")

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import sb3_er_envs  # noqa: E402,F401  (registers the ids)
from sb3_er_envs.leo import LeoEnv, ObservingGait, RenderingUnavailable, save_episode_video  # noqa: E402
from sb3_er_envs.leo import leo as leo_domain  # noqa: E402

G = 9.81
# Reference section 1: raw torso and boom constants.
TORSO_MASS, TORSO_IYY, TORSO_CM = 0.91326, 0.004676374, (-0.00102, 0.009945)
HIP_ANCHOR = (0.00273, -0.120775)
BOOM_MASS, BOOM_CMY, BOOM_IZZ, BOOM_LENGTH = 0.860, 0.835, 0.31863, 1.70
BOOM_MASS_X = (BOOM_CMY**2 * BOOM_MASS + BOOM_IZZ) / BOOM_LENGTH**2
BOOM_MASS_Z = BOOM_MASS * BOOM_CMY / BOOM_LENGTH
LIMB_MASSES = 0.095 + 2 * (0.17978 + 0.12691 + 0.07319)


@pytest.fixture(scope="module")
def physics():
    return leo_domain.load_physics()


def run_gait(env: LeoEnv, seed: int):
    """Walk one episode with Erik's gait; return per-step observations, rewards and infos."""
    gait = ObservingGait()
    gait.reset()
    observation, info = env.reset(seed=seed)
    observations, rewards, infos = [observation], [], [info]
    terminated = truncated = False
    while not (terminated or truncated):
        observation, reward, terminated, truncated, info = env.step(gait.action(observation, info))
        observations.append(observation)
        rewards.append(reward)
        infos.append(info)
    return np.array(observations), np.array(rewards), infos, terminated, truncated


@pytest.fixture(scope="module")
def gait_episode():
    env = LeoEnv(start_noise=0.05)
    raw_rates = []
    step = env.step

    def recording_step(action):
        result = step(action)
        raw_rates.append(
            {
                name: env.physics.joint_rate(name)
                for name in ("hip_left", "hip_right", "knee_left", "knee_right", "torso")
            }
        )
        return result

    env.step = recording_step
    observations, rewards, infos, terminated, truncated = run_gait(env, seed=3)
    env.close()
    return observations, rewards, infos, terminated, truncated, raw_rates


# --- the model against the reference -------------------------------------------------------------------------------


def test_total_mass_includes_the_boom_virtual_mass(physics):
    assert physics.total_mass() == pytest.approx(TORSO_MASS + BOOM_MASS_X + LIMB_MASSES, abs=1e-6)
    assert physics.total_mass() == pytest.approx(2.08575, abs=1e-5)
    assert physics.total_mass() - BOOM_MASS_X == pytest.approx(1.76802, abs=1e-5)


def test_torso_carries_the_boom_mass_at_the_hip(physics):
    model = physics.model
    torso = model.name2id("torso", "body")
    mass = TORSO_MASS + BOOM_MASS_X
    cm_x = (TORSO_MASS * TORSO_CM[0] + BOOM_MASS_X * HIP_ANCHOR[0]) / mass
    cm_z = (TORSO_MASS * TORSO_CM[1] + BOOM_MASS_X * HIP_ANCHOR[1]) / mass
    iyy = (
        TORSO_IYY
        + TORSO_MASS * ((TORSO_CM[0] - cm_x) ** 2 + (TORSO_CM[1] - cm_z) ** 2)
        + BOOM_MASS_X * ((HIP_ANCHOR[0] - cm_x) ** 2 + (HIP_ANCHOR[1] - cm_z) ** 2)
    )
    assert model.body_mass[torso] == pytest.approx(mass, abs=1e-6)
    assert model.body_ipos[torso][[0, 2]] == pytest.approx([cm_x, cm_z], abs=1e-6)
    assert model.body_inertia[torso][1] == pytest.approx(iyy, rel=1e-6)


def test_boom_force_makes_the_vertical_load_robot_plus_boom_mass_z(physics):
    with physics.reset_context():
        physics.set_pose({})
    root_z = physics.qvel_index["root_z"]
    no_contacts = int(mujoco.mjtDisableBit.mjDSBL_CONTACT)  # only gravity and the boom force act on the free robot
    physics.model.opt.disableflags |= no_contacts
    try:
        physics.forward()
        vertical = physics.data.qfrc_actuator[root_z] - physics.data.qfrc_bias[root_z]
    finally:
        physics.model.opt.disableflags &= ~no_contacts
    assert vertical == pytest.approx(-(1.76802 + BOOM_MASS_Z) * G, rel=1e-4)


def test_zero_pose_geometry_matches_the_reference(physics):
    with physics.reset_context():
        physics.set_pose({})
    anchor = {
        name: physics.data.xanchor[physics.model.name2id(name, "joint")][[0, 2]]
        for name in ("hip_left", "knee_left", "ankle_left")
    }
    assert anchor["hip_left"] - anchor["knee_left"] == pytest.approx([0.0, 0.116], abs=1e-9)
    assert anchor["knee_left"] - anchor["ankle_left"] == pytest.approx([-0.00405, 0.1045], abs=1e-9)
    heel, toe = (physics.data.geom_xpos[physics.model.name2id(name, "geom")] for name in ("heel_left", "toe_left"))
    radius = 0.0035
    assert anchor["hip_left"][1] - (heel[2] - radius) == pytest.approx(0.26909, abs=1e-9)
    assert heel[0] - anchor["ankle_left"][0] == pytest.approx(-0.0315, abs=1e-9)
    assert toe[0] - anchor["ankle_left"][0] == pytest.approx(0.0495, abs=1e-9)
    assert heel[2] == pytest.approx(radius, abs=1e-12) and toe[2] == pytest.approx(radius, abs=1e-12)


def test_joint_ranges_match_the_reference(physics):
    expected = {
        "hip": (-0.785398163397448, 2.548180707911721),
        "knee": (-2.617993877991494, 0.034906585039887),
        "ankle": (-1.570796326794897, 1.448623279155294),
    }
    model = physics.model
    for joint, limits in expected.items():
        for side in ("left", "right"):
            index = model.name2id(f"{joint}_{side}", "joint")
            assert model.jnt_limited[index]
            assert model.jnt_range[index] == pytest.approx(limits, abs=1e-12)
    assert not model.jnt_limited[model.name2id("shoulder", "joint")]


def test_start_pose_is_erik_pose_on_a_flat_left_foot():
    env = LeoEnv(start_noise=0.0)
    observation, info = env.reset(seed=0)
    expected = [-0.10, 0.0, 0.10, 0.0, 0.82, 0.0, 0.0, 0.0, -1.27, 0.0]  # Eq. 4.7, torso in the task's sign
    assert observation == pytest.approx(expected, abs=1e-12)
    physics = env.physics
    heel, toe = (physics.data.geom_xpos[physics.model.name2id(n, "geom")] for n in ("heel_left", "toe_left"))
    assert heel[[0, 2]] == pytest.approx([0.0, 0.0035], abs=1e-12)
    assert toe[2] == pytest.approx(0.0035, abs=1e-12)
    assert info["stance_leg"] == "left" and not info["stance_contact"]  # touching, not yet pressed into the floor
    assert physics.hip_position() == pytest.approx([0.02745, 0.26909], abs=2e-5)  # reference section 2, placement
    env.close()


@pytest.fixture(scope="module")
def noisy_env():
    env = LeoEnv(start_noise=0.08)
    yield env
    env.close()


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_start_noise_varies_the_pose_within_its_bound_and_keeps_the_stance_foot_flat(noisy_env, seed):
    env = noisy_env
    noise = env.task.start_noise
    first, _ = env.reset(seed=seed)
    again, _ = env.reset(seed=seed)
    assert first == pytest.approx(again, abs=0.0)
    erik = np.array([-0.10, 0.10, 0.82, 0.0, -1.27])
    angles = first[::2]
    assert np.all(np.abs(angles - erik) <= noise + 1e-12)
    assert angles[3] == 0.0  # the stance knee is not varied
    physics = env.physics
    heel, toe = (physics.data.geom_xpos[physics.model.name2id(n, "geom")] for n in ("heel_left", "toe_left"))
    assert heel[2] == pytest.approx(toe[2], abs=1e-12)
    radius = physics.model.geom_size[physics.model.name2id("heel_left", "geom"), 0]
    lowest = min(
        physics.data.geom_xpos[i, 2] - physics.model.geom_size[i, 0] for i in set(physics.model.pair_geom2.tolist())
    )  # the robot's collision geoms
    assert lowest == pytest.approx(0.0, abs=1e-12) and heel[2] >= radius - 1e-12


# --- the motor ------------------------------------------------------------------------------------------------------


def held_torso_physics():
    """LEO without gravity and contacts, its root made immovable by a huge armature: each motor turns an unloaded
    limb."""
    physics = leo_domain.load_physics()
    for root in ("root_x", "root_z", "torso"):
        physics.model.dof_armature[physics.qvel_index[root]] = 1e9
    physics.model.opt.gravity[:] = 0.0
    physics.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    with physics.reset_context():
        physics.set_pose({})
    return physics


@pytest.fixture()
def held_arm_physics():
    return held_torso_physics()


@settings(max_examples=8, deadline=None)
@given(voltage=st.floats(2.0, leo_domain.MAX_VOLTAGE), sign=st.sampled_from([-1.0, 1.0]))
def test_motor_reaches_the_speed_where_torque_balances_back_emf_and_dry_friction(voltage, sign):
    physics = held_torso_physics()
    physics.set_voltages([sign * voltage, 0, 0, 0, 0, 0, 0])
    physics.step(int(round(1.0 / physics.model.opt.timestep)))  # 1 s; time constant (armature + arm) / 0.32 ~ 0.02 s
    expected = sign * (0.166967 * voltage - 0.20) / 0.319669
    assert physics.joint_rate("shoulder") == pytest.approx(expected, rel=2e-3)


def test_dry_friction_holds_a_motor_below_its_breakaway_voltage(held_arm_physics):
    """0.9 V gives 0.15 N m, less than the 0.20 N m of dry friction. MuJoCo's friction loss is a soft constraint, so
    the joint creeps, but at a small fraction of the 0.47 rad/s it would turn at without friction."""
    held_arm_physics.set_voltages([0.9, 0, 0, 0, 0, 0, 0])
    held_arm_physics.step(600)
    assert abs(held_arm_physics.joint_rate("shoulder")) < 0.1 * 0.166967 * 0.9 / 0.319669


def test_positive_hip_voltage_swings_the_thigh_forward(held_arm_physics):
    held_arm_physics.set_voltages([0, 5.0, 0, 0, 0, 0, 0])
    held_arm_physics.step(60)
    assert held_arm_physics.joint_angle("hip_left") > 0.01
    knee = held_arm_physics.data.xanchor[held_arm_physics.model.name2id("knee_left", "joint")]
    hip = held_arm_physics.data.xanchor[held_arm_physics.model.name2id("hip_left", "joint")]
    assert knee[0] > hip[0]  # the knee moved ahead of the hip: +x is forward


@pytest.mark.parametrize("floor_parallel", [False, True])
def test_ankle_controller_holds_the_foot_at_3_72_degrees_to_the_shank_or_to_the_floor(floor_parallel):
    """Erik's default holds the ankle joint at 3.72 deg; the floor-parallel option holds the foot at 3.72 deg to the
    floor. The leg is tilted 0.4 rad, so the two differ by 0.4 rad; dry friction (0.2 N m against about 6-7 N m/rad
    of controller stiffness) leaves up to 0.035 rad of error. The stance knee's controller straightens the left knee
    meanwhile, so the leg angles are read back."""
    physics = held_torso_physics()
    task = leo_domain.LeoWalk(random=0, start_noise=0.0, floor_parallel_ankles=floor_parallel)
    with physics.reset_context():
        task.initialize_episode(physics)
        physics.set_pose({"hip_left": 0.6, "knee_left": -0.2, "hip_right": 0.6, "knee_right": -0.2})
    task.after_step(physics)
    for _ in range(30):
        task.before_step(np.zeros(3), physics)
        physics.step(leo_domain.PHYSICS_SUBSTEPS)
        task.after_step(physics)
    target = 3.72 * math.pi / 180.0
    for side in ("left", "right"):
        ankle = physics.joint_angle(f"ankle_{side}")
        foot_to_floor = sum(physics.joint_angle(name) for name in ("torso", f"hip_{side}", f"knee_{side}")) + ankle
        held = foot_to_floor if floor_parallel else ankle
        assert held == pytest.approx(target, abs=0.04)


# --- standing and walking -------------------------------------------------------------------------------------------


def test_zero_learned_voltages_for_25_s_stay_finite_and_feet_do_not_sink():
    """With 0 V on the hips LEO cannot hold its torso: it folds onto its foam bumper, but the simulation stays
    finite and no foot contact penetrates the floor by 2 mm or more (K = 2.5e4 N/m per contact)."""
    physics = leo_domain.load_physics()
    task = leo_domain.LeoWalk(random=0, start_noise=0.0)
    with physics.reset_context():
        task.initialize_episode(physics)
    feet = {physics.model.name2id(f"{part}_{side}", "geom") for part in ("heel", "toe") for side in ("left", "right")}
    deepest_foot = 0.0
    for _ in range(750):
        task.before_step(np.zeros(3), physics)
        physics.step(leo_domain.PHYSICS_SUBSTEPS)
        task.after_step(physics)
        contact = physics.data.contact
        for i in range(physics.data.ncon):
            if {int(contact.geom1[i]), int(contact.geom2[i])} & feet:
                deepest_foot = max(deepest_foot, -float(contact.dist[i]))
    assert np.all(np.isfinite(physics.data.qpos)) and np.all(np.isfinite(physics.data.qvel))
    assert 0.0 < deepest_foot < 0.002
    assert physics.max_penetration() < 0.03  # the foam bumper: weight / 1200 N/m is about 1.7 cm


def test_erik_hand_made_gait_walks_forward_for_25_s(gait_episode):
    observations, rewards, infos, terminated, truncated, _ = gait_episode
    assert truncated and not terminated
    assert len(rewards) == 750
    assert not any(info["fell"] for info in infos)
    lengths = [info["footstep_length"] for info in infos if info["footstep"]]
    longest_run = run = 0
    for length in lengths:
        run = run + 1 if length > 0 else 0
        longest_run = max(longest_run, run)
    assert longest_run >= 10
    assert infos[-1]["distance"] > 1.0
    assert infos[-1]["footsteps"] == sum(1 if length > 0 else -1 for length in lengths)


def test_discrete_and_continuous_gait_agree_on_walking():
    """The dm_control environment with continuous voltages walks like LeoEnv with the 7 levels."""
    environment = leo_domain.walk(random=5, start_noise=0.0)
    spec = environment.action_spec()
    assert spec.shape == (3,) and spec.maximum == pytest.approx(leo_domain.MAX_VOLTAGE)
    gait = ObservingGait()
    gait.reset()
    time_step = environment.reset()
    steps = 0
    while not time_step.last():
        info = environment.task.info(environment.physics)
        time_step = environment.step(gait.voltages(time_step.observation["state"], info))
        steps += 1
    assert steps == 750 and time_step.discount == 1.0
    assert environment.task.footsteps >= 30 and environment.task.distance > 5.0


def test_observation_maps_stance_and_swing_and_swaps_them_at_each_footstep(gait_episode):
    observations, _, infos, _, _, raw_rates = gait_episode
    b, a = 0.511527, 0.023055  # Erik's 10 Hz Butterworth at 30 Hz, reference 4.2
    filtered = {name: [0.0] for name in ("hip_left", "hip_right", "knee_left", "knee_right")}
    previous_raw = dict.fromkeys(filtered, 0.0)
    swaps = 0
    for k, rates in enumerate(raw_rates, start=1):
        for name in filtered:
            filtered[name].append(b * (rates[name] + previous_raw[name]) - a * filtered[name][-1])
            previous_raw[name] = rates[name]
        stance = infos[k]["stance_leg"]
        swing = "right" if stance == "left" else "left"
        expected_rates = [
            rates["torso"],
            filtered[f"hip_{stance}"][-1],
            filtered[f"hip_{swing}"][-1],
            filtered[f"knee_{stance}"][-1],
            filtered[f"knee_{swing}"][-1],
        ]
        assert observations[k][1::2] == pytest.approx(expected_rates, abs=1e-4)
        if infos[k]["footstep"]:
            swaps += 1
            assert stance != infos[k - 1]["stance_leg"]
            before, after = observations[k - 1], observations[k]
            # the new stance hip/knee continue the old swing hip/knee, and vice versa
            assert abs(after[2] - before[4]) < abs(after[2] - before[2])
            assert abs(after[4] - before[2]) < abs(after[4] - before[4])
            assert abs(after[6] - before[8]) < abs(after[6] - before[6])
    assert swaps >= 20


def test_reward_is_time_energy_swing_progress(gait_episode):
    observations, rewards, infos, _, _, _ = gait_episode

    def swing_ahead(observation):
        torso, stance_hip, swing_hip, stance_knee, swing_knee = observation[::2]
        ankle = [
            0.116 * math.sin(torso + hip) + 0.1045 * math.sin(torso + hip + knee)
            for hip, knee in ((stance_hip, stance_knee), (swing_hip, swing_knee))
        ]
        return ankle[1] - ankle[0]

    for k in range(len(rewards)):
        info = infos[k + 1]
        now = swing_ahead(observations[k + 1])
        progress = -now if info["footstep"] else now  # Erik measures the footstep's own step in the old roles
        expected = -1.0 - 3.0 * info["energy"] + 300.0 * (progress - swing_ahead(observations[k]))
        assert rewards[k] == pytest.approx(expected, abs=1e-9)
        assert info["energy"] >= 0.0
    assert sum(info["energy"] for info in infos[1:]) > 1.0


def test_fall_terminates_with_the_fall_penalty():
    env = LeoEnv(start_noise=0.0)
    env.reset(seed=0)
    zero_volts = np.array([3, 3, 3])
    for _ in range(200):
        _, reward, terminated, truncated, info = env.step(zero_volts)
        if terminated:
            break
    assert terminated and not truncated and info["fell"]
    assert reward < -110.0
    torso, stance_hip = env.task.stance_observation()[[0, 2]]
    assert abs(torso) > 1.0 or abs(torso + stance_hip) > 0.36 * math.pi
    env.close()


def test_time_limit_truncates():
    env = LeoEnv(start_noise=0.0, time_limit=0.5)
    gait = ObservingGait()
    observation, info = env.reset(seed=0)
    for step in range(15):
        observation, _, terminated, truncated, info = env.step(gait.action(observation, info))
        assert not terminated
        assert truncated == (step == 14)
    env.close()


# --- contract, errors, rendering ------------------------------------------------------------------------------------


def test_registered_env_exposes_the_contract():
    env = gym.make("sb3_er/Leo-v0")
    leo = env.unwrapped
    assert env.spec.max_episode_steps is None
    assert env.action_space == gym.spaces.MultiDiscrete([7, 7, 7])
    assert env.observation_space.shape == (10,)
    assert leo.tile_widths == pytest.approx([0.14, 5, 0.28, 10, 0.28, 10, 0.28, 10, 0.28, 10])
    assert leo.action_tile_widths == pytest.approx([6.67, 6.67, 6.67])
    assert leo.dt == pytest.approx(1.0 / 30.0)
    for values in leo.action_values:
        assert values == pytest.approx([k * 10.69189 / 3.0 for k in range(-3, 4)])
    observation, info = env.reset(seed=1)
    assert env.observation_space.contains(observation)
    assert {"footstep", "distance", "fell", "energy"} <= set(info)
    env.close()


def test_substeps_divide_the_control_step_exactly(physics):
    assert physics.model.opt.timestep * leo_domain.PHYSICS_SUBSTEPS == pytest.approx(1.0 / 30.0, abs=1e-15)


def test_contacts_are_explicit_floor_pairs_with_the_parameters_mujoco_mixed_before():
    """Only the floor against the 7 rubber spheres and the 3 foam bumpers collides, through explicit pairs (no
    broad-phase search). Their parameters are what MuJoCo's default mixing made of the geom values before the pairs
    (mean solref/solimp at solmix 1, larger friction), so the contacts did not change: the rubber's designed
    (0.0083, 0.78) / (0.99, 0.999, 0.001) and the floor's defaults (0.02, 1) / (0.9, 0.95, 0.001), friction 2."""
    model = leo_domain.load_physics().model
    assert not model.geom_contype.any() and not model.geom_conaffinity.any()
    floor = model.name2id("floor", "geom")
    rubber = {"hand", "knee_left", "heel_left", "toe_left", "knee_right", "heel_right", "toe_right"}
    foam = {"assbumper", "shoulder_front", "shoulder_back"}
    assert model.pair_geom1.tolist() == [floor] * 10
    assert {model.id2name(g, "geom") for g in model.pair_geom2} == rubber | foam
    assert list(model.pair_geom2) == sorted(model.pair_geom2)  # geom order: contacts come in the old order
    mixed_rubber = (
        [0.5 * 0.0083 + 0.5 * 0.02, 0.5 * 0.78 + 0.5 * 1.0],
        [0.5 * 0.99 + 0.5 * 0.9, 0.5 * 0.999 + 0.5 * 0.95, 0.001, 0.5, 2.0],
    )
    for pair, geom in enumerate(model.pair_geom2):
        solref, solimp = (
            mixed_rubber if model.id2name(geom, "geom") in rubber else ([0.02, 1.0], [0.9, 0.95, 0.001, 0.5, 2.0])
        )
        assert model.pair_solref[pair].tolist() == solref
        assert model.pair_solimp[pair].tolist() == solimp
        assert model.pair_friction[pair].tolist() == [2.0, 2.0, 0.005, 0.0001, 0.0001]
        assert model.pair_dim[pair] == 3 and model.pair_margin[pair] == 0.0 and model.pair_gap[pair] == 0.0


def test_step_control_is_dm_control_physics_step_bit_for_bit():
    """Physics.step_control (MuJoCo called directly, quiet timer clock) leaves exactly the data dm_control's
    Physics.step leaves: state, warm start, contacts and the kinematics the task reads."""
    twins = [leo_domain.load_physics() for _ in range(2)]
    task = leo_domain.LeoWalk(random=0, start_noise=0.0)
    for physics in twins:
        with physics.reset_context():
            task.initialize_episode(physics)
    rng = np.random.default_rng(0)
    for step in range(60):
        voltages = rng.uniform(-leo_domain.MAX_VOLTAGE, leo_domain.MAX_VOLTAGE, size=7)
        for physics in twins:
            physics.set_voltages(voltages)
        twins[0].step(leo_domain.PHYSICS_SUBSTEPS)
        twins[1].step_control(leo_domain.PHYSICS_SUBSTEPS)
        a, b = (physics.data.ptr for physics in twins)
        for field in ("qpos", "qvel", "qacc", "qacc_warmstart", "xanchor", "geom_xpos", "efc_force", "time"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), (step, field)
        assert a.ncon == b.ncon and np.array_equal(a.contact.geom, b.contact.geom)
        assert np.array_equal(a.contact.dist, b.contact.dist)
    assert mujoco.get_mjcb_time() is None  # the quiet clock is only in place during the step


def test_reset_for_leaves_the_data_of_dm_controls_reset_context():
    """LeoEnv's reset (Physics.reset_for, two mj_forward calls fewer) leaves exactly the data and task state that
    ``with physics.reset_context(): task.initialize_episode(physics)`` leaves, also after an episode has run."""
    twins = [leo_domain.load_physics() for _ in range(2)]
    tasks = [leo_domain.LeoWalk(random=7, start_noise=0.08) for _ in range(2)]
    for episode in range(3):
        with twins[0].reset_context():
            tasks[0].initialize_episode(twins[0])
        twins[1].reset_for(tasks[1])
        a, b = (physics.data.ptr for physics in twins)
        for field in (
            "qpos",
            "qvel",
            "qacc",
            "qacc_warmstart",
            "qfrc_actuator",
            "actuator_force",
            "efc_force",
            "xanchor",
            "geom_xpos",
            "ctrl",
            "time",
            "qM",
            "cinert",
        ):
            field = "M" if field == "qM" and not hasattr(a, "qM") else field
            assert np.array_equal(getattr(a, field), getattr(b, field)), (episode, field)
        assert a.ncon == b.ncon and np.array_equal(a.contact.dist, b.contact.dist)
        assert tasks[0].stance_values() == tasks[1].stance_values()
        assert tasks[0].stance_contact == tasks[1].stance_contact
        for physics, task in zip(twins, tasks, strict=True):
            for _ in range(20):
                task.apply_voltages(2.0, -3.0, 1.0, physics)
                physics.step_control(leo_domain.PHYSICS_SUBSTEPS)
                task.after_step(physics)


def test_step_control_keeps_mujoco_timers_on_request_and_leaves_a_user_clock_alone():
    physics = leo_domain.load_physics()
    with physics.reset_context():
        physics.set_pose({})
    step_timer = physics.data.ptr.timer[mujoco.mjtTimer.mjTIMER_STEP]
    physics.step_control(30)
    assert step_timer.number == 30 and step_timer.duration == 0.0
    physics.keep_mujoco_timers = True
    physics.step_control(30)
    assert step_timer.number == 60 and step_timer.duration > 0.0
    physics.keep_mujoco_timers = False
    clock = [0.0]

    def user_clock():
        clock[0] += 1.0
        return clock[0]

    mujoco.set_mjcb_time(user_clock)
    try:
        physics.step_control(2)
        assert mujoco.get_mjcb_time() is user_clock and clock[0] > 0.0
    finally:
        mujoco.set_mjcb_time(None)


def test_step_control_raises_physics_error_like_dm_control():
    from dm_control.rl.control import PhysicsError

    physics = leo_domain.load_physics()
    with physics.reset_context():
        physics.set_pose({})
    physics.data.qvel[:] = np.nan
    with pytest.raises(PhysicsError, match="invalid.*mjWARN_BAD"):
        physics.step_control(30)
    physics.data.qvel[:] = np.nan
    with physics.suppress_physics_errors():
        physics.step_control(30)  # logged, not raised
    assert np.all(np.isfinite(physics.data.qvel))  # MuJoCo reset the diverged state


@pytest.mark.parametrize(
    "action",
    [np.array([1, 3, 6]), np.array([1, 3, 6], dtype=np.int32), [1, 3, 6], np.array([1.0, 3.0, 6.0]), (1, 3, 6)],
)
def test_every_form_of_a_valid_action_gives_the_same_step(action):
    results = []
    for form in (np.array([1, 3, 6]), action):
        env = LeoEnv(start_noise=0.0)
        env.reset(seed=0)
        observation, reward, _, _, info = env.step(form)
        results.append((observation, reward, info["energy"], env.physics.data.ctrl.copy()))
        env.close()
    (obs_a, reward_a, energy_a, ctrl_a), (obs_b, reward_b, energy_b, ctrl_b) = results
    assert np.array_equal(obs_a, obs_b) and reward_a == reward_b and energy_a == energy_b
    assert np.array_equal(ctrl_a, ctrl_b)


def test_gait_action_is_the_nearest_voltage_level():
    from sb3_er_envs.leo.gait import _nearest_level

    levels = leo_domain.VOLTAGE_LEVELS
    rng = np.random.default_rng(0)
    voltages = np.concatenate(
        [rng.uniform(-12.0, 12.0, 2000), levels, (levels[:-1] + levels[1:]) / 2.0, [-20.0, 20.0, 0.0, -0.0]]
    )
    for voltage in voltages:
        assert _nearest_level(float(voltage)) == int(np.abs(voltage - levels).argmin())


@pytest.mark.parametrize("action", [[0, 0, 7], [0, -1, 0], [3, 3], [0.5, 3, 3]])
def test_bad_action_is_refused(action):
    env = LeoEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="3 voltage levels"):
        env.step(np.array(action))
    env.close()


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="start_noise"):
        LeoEnv(start_noise=-0.1)
    with pytest.raises(ValueError, match="render_mode"):
        LeoEnv(render_mode="human")
    with pytest.raises(ValueError, match="camera"):
        LeoEnv(camera="top")
    with pytest.raises(ValueError, match="explore_rate"):
        ObservingGait(explore_rate=2.0)


def test_missing_dm_control_names_the_extra():
    code = (
        "import sys; sys.modules['dm_control'] = None\n"
        "import sb3_er_envs.leo as leo\n"
        "try:\n    leo.LeoEnv\nexcept ImportError as error:\n    print(error)\n"
    )
    output = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout
    assert "sb3-er[dmc]" in output


def _render_or_skip(env):
    """A frame, or a skip when this machine has no OpenGL backend; CI installs one, so there a skip is a failure."""
    try:
        return env.render()
    except RenderingUnavailable as error:
        if os.environ.get("CI", "").lower() in ("true", "1"):
            pytest.fail(f"CI must render LEO: {error}")
        pytest.skip(f"no OpenGL backend for MuJoCo rendering here: {error}")


_WITHOUT_GL = """
import os, sys
os.environ.pop("DISPLAY", None); os.environ.pop("WAYLAND_DISPLAY", None)
import sb3_er_envs.leo._gl as gl
gl._loadable = lambda name: False          # as on a machine without libEGL, libGL and libOSMesa
import gymnasium as gym, sb3_er_envs
from sb3_er_envs.leo import RenderingUnavailable
env = gym.make("sb3_er/Leo-v0", render_mode="rgb_array")
env.reset(seed=0)
for _ in range(30):
    observation, reward, terminated, truncated, info = env.step([3, 3, 3])
print("STEPPED", observation.shape, bool(terminated or truncated) or info["distance"] is not None)
print("MUJOCO_GL after import:", os.environ.get("MUJOCO_GL"))
try:
    env.render()
except RenderingUnavailable as error:
    print("RENDER ERROR:", error)
"""


def _run_without_gl(mujoco_gl):
    env = {key: value for key, value in os.environ.items() if key not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    if mujoco_gl is not None:
        env["MUJOCO_GL"] = mujoco_gl
    result = subprocess.run([sys.executable, "-c", _WITHOUT_GL], capture_output=True, text=True, timeout=300, env=env)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_leo_simulates_on_a_machine_without_any_opengl_library():
    output = _run_without_gl(None)
    assert "STEPPED (10,)" in output
    assert "MUJOCO_GL after import: None" in output  # the package leaves no backend behind
    error = output.split("RENDER ERROR:")[1]
    for words in ("libOSMesa", "libEGL", "MUJOCO_GL", "Simulation works"):
        assert words in error


@pytest.mark.parametrize("backend, library", [("osmesa", "libOSMesa"), ("egl", "libEGL")])
def test_a_requested_backend_without_its_library_still_simulates(backend, library):
    output = _run_without_gl(backend)
    assert "STEPPED (10,)" in output
    assert f"MUJOCO_GL={backend}" in output and library in output.split("RENDER ERROR:")[1]


def test_makefile_forces_no_backend():
    makefile = (Path(__file__).resolve().parents[1] / "Makefile").read_text()
    assert "MUJOCO_GL" not in makefile and "PYOPENGL_PLATFORM" not in makefile


def test_rgb_array_rendering_shows_the_robot():
    env = LeoEnv(render_mode="rgb_array", render_size=(120, 160), start_noise=0.0)
    env.reset(seed=0)
    frame = _render_or_skip(env)
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8
    assert frame.std() > 5.0
    env.close()


def test_episode_video_is_written(tmp_path):
    env = LeoEnv(render_mode="rgb_array", render_size=(96, 128), start_noise=0.0)
    env.reset(seed=0)
    _render_or_skip(env)
    import imageio.v2 as imageio

    summary = save_episode_video(tmp_path / "gait.gif", env=env, seed=0, fps=10.0, max_steps=30)
    assert summary["steps"] == 30 and not summary["fell"]
    frames = imageio.mimread(tmp_path / "gait.gif")
    assert len(frames) == 1 + 30 // 3
    with pytest.raises(ValueError, match="gif or .mp4"):
        save_episode_video(tmp_path / "gait.avi", env=env)
    env.close()
