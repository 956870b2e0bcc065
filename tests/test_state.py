"""The state is the whole state: a rollout from ``env.get_state()`` is what ``env.step`` does.

The learned dynamics steps from a pose history; it travels in ``MjData.userdata``
(``mjSTATE_USERDATA`` in ``STATE_SPEC``), so a state taken mid-push or mid-toss restarts exactly
where the environment is, for single and vector environments, and for both backends.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from sim_factories import quiet_simulator

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.dynamics import (
    STATE_SPEC,
    FIGNetDynamics,
    MujocoDynamics,
    compile_with_history,
    userdata_slice,
)
from fignet_gym.mjcf import push_scene_xml

#: Float tolerance of a learned rollout against stepping: the same float32 network on the same
#: inputs, batched differently.
LEARNED_ATOL = 1e-5
TOSS_FAST = {"settle_steps": 6}


def _rows(nstep: int, frame_skip: int) -> np.ndarray:
    """Control rows ``float[1, T, 0]`` of a model without mocap bodies: ``T = nstep //
    frame_skip`` recorded states of ``nstep`` MuJoCo timesteps."""
    return np.zeros((1, nstep // frame_skip, 0))


def _noisy_push(env: gym.Env, steps: int, seed: int) -> np.ndarray:
    """Drive the tip into the object with noise for ``steps`` steps; the next action ``float[2]``."""
    u = env.unwrapped
    rng = np.random.default_rng(seed)

    def action() -> np.ndarray:
        s = u.get_state()
        to_obj = u.task.object_pose(s)[:2] - u.task.tip_xy(s)
        return np.clip(to_obj / np.linalg.norm(to_obj) + rng.normal(0, 0.3, 2), -1, 1)

    for _ in range(steps):
        env.step(action())
    return action()


@pytest.mark.parametrize("dynamics", ["fignet", "mujoco"])
def test_push_rollout_from_a_mid_push_state_is_the_env_step(dynamics: str) -> None:
    env = gym.make("fignet_gym/Push-v1", dynamics=dynamics)
    u = env.unwrapped
    env.reset(seed=1)
    a = _noisy_push(env, 12, seed=0)
    start = u.get_state()
    moved = np.linalg.norm(u.task.object_pose(start)[:2])
    assert moved > 1e-3, "the pusher must be pushing the object"
    actions = np.stack([a, a * 0.5, -a])[None]
    pred = u.dynamics.rollout(u.model, start, u.task.controls(start[None], actions),
                              frame_skip=u.frame_skip)[0]
    for t in range(3):
        env.step(actions[0, t])
        np.testing.assert_allclose(pred[t], u.get_state(), rtol=0,
                                   atol=LEARNED_ATOL if dynamics == "fignet" else 1e-9)


def test_push_vector_env_rows_roll_out_as_they_step() -> None:
    venv = gym.make_vec("fignet_gym/Push-v1", num_envs=3, vectorization_mode="vector_entry_point",
                        dynamics="fignet")
    venv.reset(seed=5)
    rng = np.random.default_rng(0)
    envs = venv.unwrapped.envs
    for _ in range(8):
        tips = np.stack([e.task.tip_xy(e.get_state()) for e in envs])
        objs = np.stack([e.task.object_pose(e.get_state())[:2] for e in envs])
        act = np.clip((objs - tips) * 50 + rng.normal(0, 0.3, (3, 2)), -1, 1)
        venv.step(act)
    states = np.stack([e.get_state() for e in envs])
    act = rng.uniform(-1, 1, (3, 1, 2))
    control = np.concatenate([e.task.controls(s[None], a[None]) for e, s, a in
                              zip(envs, states, act, strict=True)])
    pred = envs[0].dynamics.rollout(envs[0].model, states, control, frame_skip=envs[0].frame_skip)
    venv.step(act[:, 0])
    for i, e in enumerate(envs):
        np.testing.assert_allclose(pred[i, 0], e.get_state(), rtol=0, atol=LEARNED_ATOL)
    venv.close()


def test_toss_rollout_continues_from_a_mid_toss_state() -> None:
    """One settle rolled out whole, and from a state half way: the same trajectory."""
    dyn = FIGNetDynamics(quiet_simulator("toss"))
    env = gym.make("fignet_gym/Toss-v0", dynamics=dyn, **TOSS_FAST)
    u = env.unwrapped
    env.reset(seed=2)
    env.step(np.array([0.3, -0.2]))
    released = u.task.release(u.get_state(), u.released, float(u.release_yaws[u.released]),
                              np.array([0.5, 0.1]))
    skip = u.settle_frame_skip
    n = u.settle_steps * skip
    whole = dyn.rollout(u.model, released, _rows(n, skip), nstep=n, frame_skip=skip)[0]
    half = u.settle_steps // 2
    n = (u.settle_steps - half) * skip
    rest = dyn.rollout(u.model, whole[half - 1], _rows(n, skip), nstep=n, frame_skip=skip)[0]
    np.testing.assert_allclose(rest, whole[half:], rtol=0, atol=LEARNED_ATOL)
    # and the env's own step from the released state ends where the rollout does
    u.set_state(released)
    u.released += 1  # the release is already in the state
    dyn.step(u.model, u.data, u.frame_skip)
    np.testing.assert_allclose(u.get_state(), whole[-1], rtol=0, atol=LEARNED_ATOL)


def test_toss_vector_env_rows_roll_out_as_they_step() -> None:
    dyn = FIGNetDynamics(quiet_simulator("toss"))
    venv = gym.make_vec("fignet_gym/Toss-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        dynamics=dyn, **TOSS_FAST)
    venv.reset(seed=3)
    venv.step(np.array([[0.3, -0.2], [-0.5, 0.4]]))
    envs = venv.unwrapped.envs
    act = np.array([[0.1, 0.2], [0.7, -0.3]])
    released = np.stack([e.task.release(e.get_state(), e.released, float(e.release_yaws[e.released]),
                                        a) for e, a in zip(envs, act, strict=True)])
    n = envs[0].frame_skip
    pred = dyn.rollout(envs[0].model, released, _rows(n, n), nstep=n, frame_skip=n)
    venv.step(act)
    for i, e in enumerate(envs):
        np.testing.assert_allclose(pred[i, -1], e.get_state(), rtol=0, atol=LEARNED_ATOL)
    venv.close()


@pytest.mark.parametrize("vector", [False, True])
def test_cube_toss_rollout_is_the_env_step_and_continues_mid_toss(vector: bool) -> None:
    kwargs = {"dynamics": "fignet", "checkpoint": "cube-real"}
    if vector:
        env = gym.make_vec("fignet_gym/CubeToss-v0", num_envs=2,
                           vectorization_mode="vector_entry_point", **kwargs)
        envs = env.unwrapped.envs
    else:
        env = gym.make("fignet_gym/CubeToss-v0", **kwargs)
        envs = [env.unwrapped]
    env.reset(seed=4)
    u = envs[0]
    acts = np.random.default_rng(1).uniform(-1, 1, (len(envs), 6))
    released = []
    for e, a in zip(envs, acts, strict=True):  # the release, written as the env writes it
        saved = e.get_state()
        e._apply_action(a)
        released.append(e.get_state())
        e.set_state(saved)
        e.tossed = False
    released = np.stack(released)
    skip = u.settle_frame_skip
    n = u.frame_skip
    pred = u.dynamics.rollout(u.model, released, _rows(n, skip), nstep=n, frame_skip=skip)
    env.step(acts if vector else acts[0])
    for i, e in enumerate(envs):
        np.testing.assert_allclose(pred[i, -1], e.get_state(), rtol=0, atol=LEARNED_ATOL)
    half = pred.shape[1] // 2
    rest = u.dynamics.rollout(u.model, pred[:, half - 1], _rows((pred.shape[1] - half) * skip, skip),
                              nstep=(pred.shape[1] - half) * skip, frame_skip=skip)
    np.testing.assert_allclose(rest, pred[:, half:], rtol=0, atol=LEARNED_ATOL)
    env.close()


def test_state_from_mujoco_stepping_gives_the_learned_model_the_real_trajectory() -> None:
    """MuJoCo records its trajectory in the state too: a learned rollout from a MuJoCo-stepped
    state uses those past poses (the pusher moving), not a made-up history (the pusher at rest)."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.06, 0.0)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mj = MujocoDynamics(nthread=1)
    for _ in range(3):
        data.mocap_pos[0, 0] += 0.002
        mj.step(model, data, 10)
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    fresh = state.copy()
    fresh[userdata_slice(model)] = 0.0  # the same physics without a past
    learned = FIGNetDynamics("push")
    control = np.concatenate((data.mocap_pos[0] + [0.002, 0, 0], data.mocap_quat[0]))[None, None]
    a = learned.rollout(model, state, control, frame_skip=10)
    b = learned.rollout(model, fresh, control, frame_skip=10)
    # MuJoCo's own history: the learned step from it equals its step from data with that past
    d2 = mujoco.MjData(model)
    mujoco.mj_setState(model, d2, state, STATE_SPEC)
    mujoco.mj_forward(model, d2)
    d2.mocap_pos[0] = control[0, 0, :3]
    learned.step(model, d2, 10)
    got = np.empty_like(state)
    mujoco.mj_getState(model, d2, got, STATE_SPEC)
    np.testing.assert_allclose(a[0, 0], got, rtol=0, atol=LEARNED_ATOL)
    assert not np.allclose(a[0, 0, 1:8], b[0, 0, 1:8], atol=1e-7), "the history must matter"


@pytest.mark.parametrize("backend", ["mujoco", "fignet"])
def test_empty_batch_and_zero_steps_give_empty_arrays(backend: str) -> None:
    model = compile_with_history(push_scene_xml("rect1"))
    dyn = MujocoDynamics(nthread=1) if backend == "mujoco" else FIGNetDynamics(quiet_simulator())
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    out = dyn.rollout(model, np.zeros((0, nstate)), np.zeros((0, 4, 7)), frame_skip=10)
    assert out.shape == (0, 4, nstate)
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)
    state = np.empty(nstate)
    mujoco.mj_getState(model, d, state, STATE_SPEC)
    out = dyn.rollout(model, np.stack([state, state]), np.zeros((2, 0, 7)), frame_skip=10)
    assert out.shape == (2, 0, nstate)
    # nstep counts timesteps: its pre-release meaning (recorded states) is refused, naming the fix
    control = np.concatenate((d.mocap_pos[0], d.mocap_quat[0]))[None, None].repeat(3, 1)
    with pytest.raises(ValueError, match="not a multiple of frame_skip=10.*nstep=30"):
        dyn.rollout(model, state, control, nstep=3, frame_skip=10)
    with pytest.raises(ValueError, match="control has 20 rows.*pass nstep=200"):
        dyn.rollout(model, state, control.repeat(7, 1)[:, :20], nstep=20, frame_skip=10)
    assert dyn.rollout(model, state, control, nstep=30, frame_skip=10).shape == (1, 3, nstate)


def test_nstep_counts_timesteps_without_control_rows() -> None:
    """Without control (no mocap bodies) too: before the first release nstep meant recorded
    states there."""
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><option gravity="0 0 0" timestep="0.01"/><worldbody><body><freejoint/>'
        '<geom type="sphere" size="0.05" mass="1"/></body></worldbody></mujoco>')
    state = np.zeros(mujoco.mj_stateSize(model, STATE_SPEC))
    state[4] = 1.0  # the identity quaternion of the ball, at rest at the origin
    dyn = MujocoDynamics(nthread=1)
    out = dyn.rollout(model, state, nstep=30, frame_skip=10)
    assert out.shape == (1, 3, len(state))
    np.testing.assert_allclose(out[0, :, 0], [0.1, 0.2, 0.3])  # time: 10 timesteps of 0.01 s each
    np.testing.assert_array_equal(out, dyn.rollout(model, state, np.zeros((1, 3, 0)), nstep=30,
                                                   frame_skip=10))


@pytest.mark.parametrize("backend", ["mujoco", "fignet"])
def test_zero_quaternion_is_normalised_as_mujoco_does(backend: str) -> None:
    """MuJoCo treats a zero quaternion as the identity; so does the learned rollout."""
    model = compile_with_history(push_scene_xml("rect1"))
    dyn = MujocoDynamics(nthread=1) if backend == "mujoco" else FIGNetDynamics("push")
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    good = np.empty(nstate)
    mujoco.mj_getState(model, d, good, STATE_SPEC)
    qa = int(model.jnt_qposadr[0])
    zero = good.copy()
    zero[1 + qa + 3 : 1 + qa + 7] = 0.0  # the object's quaternion
    control = np.concatenate((d.mocap_pos[0], d.mocap_quat[0]))[None, None].repeat(3, 1)
    a = dyn.rollout(model, zero, control, frame_skip=10)
    b = dyn.rollout(model, good, control, frame_skip=10)
    assert np.isfinite(a).all()
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    # a zero mocap quaternion too: the identity, as MuJoCo normalises it (no 0/0 on the way)
    control[..., 3:] = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        c = dyn.rollout(model, good, control, frame_skip=10)
    assert np.isfinite(c).all()
    control[..., 3] = 1.0
    qpos = slice(1, 1 + model.nq)  # time, then qpos (the stored mocap target stays as given)
    np.testing.assert_allclose(c[..., qpos], dyn.rollout(model, good, control, frame_skip=10)[..., qpos],
                               rtol=0, atol=1e-9)


def test_history_rebuilt_from_qvel_reads_the_angular_velocity_in_the_body_frame() -> None:
    """MuJoCo's free-joint ``qvel[3:6]`` is in the body frame. A sphere spinning in zero gravity
    (constant angular velocity) started turned away from the identity: the poses ``integrate_back``
    rebuilds k steps back are the ones MuJoCo passed through (reading the spin in the world frame
    turns the object the wrong way once it is not at the identity)."""
    import mujoco
    import torch

    from fignet_gym.dynamics.learned_ops import integrate_back

    xml = ("<mujoco><option gravity='0 0 0' timestep='0.001' integrator='RK4'/><worldbody>"
           "<body><freejoint/><geom type='sphere' size='0.05' mass='1'/></body></worldbody></mujoco>")
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    axis = np.array([0.3, -0.8, 0.5]) / np.linalg.norm([0.3, -0.8, 0.5])
    data.qpos[3:7] = np.concatenate([[np.cos(1.0)], np.sin(1.0) * axis])  # turned by 2 rad
    data.qvel[:] = [0.2, -0.1, 0.05, 3.0, 1.0, -2.0]
    dt, k, sub = 0.02, 2, 20
    past = data.qpos.copy()
    mujoco.mj_step(model, data, k * sub)
    now = torch.tensor(data.qpos[None], dtype=torch.float64)
    back = integrate_back(now, torch.tensor(data.qvel[None, :3]), torch.tensor(data.qvel[None, 3:]),
                          k, dt)[0].numpy()
    np.testing.assert_allclose(back[:3], past[:3], atol=1e-9)
    assert min(np.abs(back[3:] - past[3:]).max(), np.abs(back[3:] + past[3:]).max()) < 1e-6
