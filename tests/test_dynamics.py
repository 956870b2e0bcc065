"""The swap point: MujocoDynamics equals MuJoCo, FIGNetDynamics honours the same contract."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import pytest
import torch
from sim_factories import quiet_simulator, wild_simulator, zero_simulator

from fignet_gym.dynamics import (
    CONTROL_SPEC,
    STATE_SPEC,
    DivergenceError,
    Dynamics,
    DynamicsBase,
    FIGNetDynamics,
    MujocoDynamics,
    join_state,
    make_dynamics,
    rollout_loop,
    split_state,
    userdata_slice,
)
from fignet_gym.dynamics.history import compile_with_history
from fignet_gym.mjcf import TossObject, push_scene_xml, toss_scene_xml


@pytest.fixture(scope="module")
def push_model() -> mujoco.MjModel:
    return compile_with_history(push_scene_xml("rect1"))


@pytest.fixture(scope="module")
def toss_model() -> mujoco.MjModel:
    objs = [TossObject("cube", 0.1), TossObject("cylinder", 0.1)]
    poses = np.array([[0, 0, 0.3, 1, 0, 0, 0], [0.5, 0, 0.3, 1, 0, 0, 0]], float)
    return compile_with_history(toss_scene_xml(objs, floor_half_size=2.0, poses=poses))


def _tip_path(model: mujoco.MjModel, T: int, speed: float = 0.1, dt: float = 0.02) -> np.ndarray:
    """``float[T, 7]`` mocap control rows: the tip moving along +x towards the object."""
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)
    start = d.mocap_pos[0].copy()
    rows = np.zeros((T, 7))
    for t in range(T):
        rows[t, :3] = start + np.array([speed * dt * (t + 1), 0, 0])
        rows[t, 3:] = (1, 0, 0, 0)
    return rows


def test_protocol_conformance() -> None:
    assert isinstance(MujocoDynamics(), Dynamics)
    assert isinstance(FIGNetDynamics(zero_simulator()), Dynamics)
    with pytest.raises(ValueError, match="unknown dynamics"):
        make_dynamics("bullet")
    with pytest.raises(TypeError, match="lacks"):
        make_dynamics(object())  # type: ignore[arg-type]


#: MuJoCo's integration state without ``userdata`` (where MujocoDynamics records the pose
#: history that plain ``mj_step`` does not).
_INTEGRATION = int(mujoco.mjtState.mjSTATE_INTEGRATION) & ~int(mujoco.mjtState.mjSTATE_USERDATA)


def _integration_state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    out = np.zeros(mujoco.mj_stateSize(model, _INTEGRATION))
    mujoco.mj_getState(model, data, out, _INTEGRATION)
    return out


def test_mujoco_step_equals_mj_step_with_the_pusher_moved_each_timestep(
        push_model: mujoco.MjModel) -> None:
    a, b = mujoco.MjData(push_model), mujoco.MjData(push_model)
    for d in (a, b):
        mujoco.mj_forward(push_model, d)
    dyn = MujocoDynamics()
    path = _tip_path(push_model, 8, speed=0.5)
    for row in path:
        # Reference: plain mj_step, the tip moved by hand every timestep (as the data generator).
        start = a.mocap_pos[0].copy()
        for i in range(1, 11):
            a.mocap_pos[0] = start + (row[:3] - start) * (i / 10)
            mujoco.mj_step(push_model, a, 1)
        b.mocap_pos[0] = row[:3]
        dyn.step(push_model, b, 10)
    np.testing.assert_allclose(_integration_state(push_model, a),
                               _integration_state(push_model, b), rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.xpos, b.xpos, rtol=0, atol=1e-12)


def test_mujoco_step_is_mj_step_when_the_pusher_holds_still(push_model: mujoco.MjModel) -> None:
    a, b = mujoco.MjData(push_model), mujoco.MjData(push_model)
    a.qvel[0] = b.qvel[0] = 0.3
    for d in (a, b):
        mujoco.mj_forward(push_model, d)
    mujoco.mj_step(push_model, a, 10)
    MujocoDynamics().step(push_model, b, 10)
    np.testing.assert_array_equal(_integration_state(push_model, a), _integration_state(push_model, b))


def test_mujoco_rollout_equals_loop_and_mujoco_rollout(push_model: mujoco.MjModel) -> None:
    dyn = MujocoDynamics(nthread=2)
    d = mujoco.MjData(push_model)
    nstate = mujoco.mj_stateSize(push_model, STATE_SPEC)
    B, T = 3, 6
    init = np.zeros((B, nstate))
    for i in range(B):
        mujoco.mj_resetData(push_model, d)
        d.qpos[0] = 0.01 * i
        mujoco.mj_getState(push_model, d, init[i], STATE_SPEC)
    control = np.stack([_tip_path(push_model, T, speed=0.3 + 0.1 * i) for i in range(B)])
    out = dyn.rollout(push_model, init, control, frame_skip=10)
    assert out.shape == (B, T, nstate)
    for i in range(B):
        ref = rollout_loop(dyn, push_model, d, init[i], control[i], 10)
        np.testing.assert_allclose(out[i], ref, rtol=0, atol=1e-12)
    # frame_skip=1 is mujoco.rollout itself
    from mujoco import rollout as mj_rollout

    ref, _ = mj_rollout.rollout(
        push_model, mujoco.MjData(push_model), split_state(push_model, init)[0], control,
        control_spec=CONTROL_SPEC,
    )
    # ... its states, with the mocap poses (the control rows) and the pose history added
    mine = dyn.rollout(push_model, init, control)
    user = mine[..., userdata_slice(push_model)]
    np.testing.assert_allclose(mine, join_state(push_model, ref, control, user), atol=1e-12)
    dyn.close()


def test_rollout_input_checks(push_model: mujoco.MjModel) -> None:
    dyn = MujocoDynamics()
    nstate = mujoco.mj_stateSize(push_model, STATE_SPEC)
    with pytest.raises(ValueError, match="initial_state"):
        dyn.rollout(push_model, np.zeros((2, nstate + 1)), np.zeros((2, 3, 7)))
    with pytest.raises(ValueError, match="control"):
        dyn.rollout(push_model, np.zeros((2, nstate)), np.zeros((2, 3, 5)))
    with pytest.raises(ValueError, match="NaN"):
        dyn.rollout(push_model, np.full((1, nstate), np.nan), np.zeros((1, 3, 7)))


def test_fignet_step_contract(push_model: mujoco.MjModel) -> None:
    dyn = FIGNetDynamics(quiet_simulator())
    d = mujoco.MjData(push_model)
    mujoco.mj_forward(push_model, d)
    d.mocap_pos[0, 0] += 0.002
    dyn.step(push_model, d, 10)
    assert d.time == pytest.approx(0.02)
    q = d.qpos[3:7]
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-6)
    # mj_forward ran: derived quantities follow qpos and mocap
    body = mujoco.mj_name2id(push_model, mujoco.mjtObj.mjOBJ_BODY, "object")
    tip = mujoco.mj_name2id(push_model, mujoco.mjtObj.mjOBJ_BODY, "tip")
    np.testing.assert_allclose(d.xpos[body], d.qpos[:3])
    np.testing.assert_allclose(d.xpos[tip], d.mocap_pos[0])
    with pytest.raises(ValueError, match="whole number of learned steps"):
        dyn.step(push_model, d, 7)
    dyn.step(push_model, d, 30)  # three learned steps
    assert d.time == pytest.approx(0.08)


def test_fignet_honours_initial_velocity(toss_model: mujoco.MjModel) -> None:
    """With zero predicted acceleration an object keeps the velocity it was given in qvel.

    Nodes then move on straight lines, which a rotation only approximates: the fitted angular
    velocity is off by ~(|w| dt)^2 = 0.2 %, hence the angular tolerance.
    """
    dyn = FIGNetDynamics(zero_simulator())
    d, ref = mujoco.MjData(toss_model), mujoco.MjData(toss_model)
    v = np.array([0.5, -0.2, 0.3, 1.0, -2.0, 0.5])  # linear world, angular body
    for x in (d, ref):
        mujoco.mj_forward(toss_model, x)
        x.qvel[:6] = v
    p0 = d.qpos[:3].copy()
    dyn.step(toss_model, d, 10)
    np.testing.assert_allclose(d.qpos[:3], p0 + 0.02 * v[:3], atol=1e-5)
    np.testing.assert_allclose(d.qvel[:6], v, rtol=5e-3, atol=1e-5)
    # the learned history continues: a second step keeps the velocity
    dyn.step(toss_model, d, 10)
    np.testing.assert_allclose(d.qvel[:6], v, rtol=1e-2, atol=1e-5)
    # editing one object's qvel (a release) reseeds that object only
    dyn.step(toss_model, ref, 20)
    d.qvel[6:9] = (0.0, 1.0, 0.0)
    p1 = d.qpos[7:10].copy()
    dyn.step(toss_model, d, 10)
    dyn.step(toss_model, ref, 10)
    np.testing.assert_allclose(d.qpos[7:10], p1 + [0.0, 0.02, 0.0], atol=1e-5)
    np.testing.assert_allclose(d.qpos[:7], ref.qpos[:7], atol=1e-6)


def test_fignet_step_many_equals_single_steps(push_model: mujoco.MjModel) -> None:
    dyn_a = FIGNetDynamics(quiet_simulator())
    dyn_b = FIGNetDynamics(dyn_a.simulator)
    singles = [mujoco.MjData(push_model) for _ in range(3)]
    batch = [mujoco.MjData(push_model) for _ in range(3)]
    for i, (s, b) in enumerate(zip(singles, batch, strict=True)):
        for d in (s, b):
            d.qpos[0] = 0.01 * i
            d.qvel[5] = 0.5 * i
            mujoco.mj_forward(push_model, d)
    for _ in range(4):
        for i, (s, b) in enumerate(zip(singles, batch, strict=True)):
            for d in (s, b):
                d.mocap_pos[0, 0] += 0.002 * (i + 1)
        for s in singles:
            dyn_a.step(push_model, s, 10)
        dyn_b.step_many(push_model, batch, 10)
    for s, b in zip(singles, batch, strict=True):
        np.testing.assert_allclose(s.qpos, b.qpos, atol=1e-5)
        np.testing.assert_allclose(s.qvel, b.qvel, atol=1e-3)
        assert s.time == b.time


def test_fignet_rollout_equals_loop(push_model: mujoco.MjModel) -> None:
    dyn = FIGNetDynamics(quiet_simulator())
    d = mujoco.MjData(push_model)
    nstate = mujoco.mj_stateSize(push_model, STATE_SPEC)
    B, T = 2, 4
    init = np.zeros((B, nstate))
    for i in range(B):
        mujoco.mj_resetData(push_model, d)
        d.qpos[1] = 0.02 * i
        d.qvel[0] = 0.1 * i
        mujoco.mj_getState(push_model, d, init[i], STATE_SPEC)
    control = np.stack([_tip_path(push_model, T, speed=0.2 * (i + 1)) for i in range(B)])
    out = dyn.rollout(push_model, init, control, frame_skip=10)
    assert out.shape == (B, T, nstate)
    for i in range(B):
        ref = rollout_loop(dyn, push_model, d, init[i], control[i], 10)
        np.testing.assert_allclose(out[i], ref, atol=1e-5)


def test_fignet_divergence_is_reported(push_model: mujoco.MjModel) -> None:
    dyn = FIGNetDynamics(wild_simulator())
    d = mujoco.MjData(push_model)
    mujoco.mj_forward(push_model, d)
    before = d.qpos.copy()
    with pytest.raises(DivergenceError, match="object 'object'") as err:
        dyn.step(push_model, d, 10)
    assert err.value.indices == (0,)
    np.testing.assert_array_equal(d.qpos, before)  # left as it was
    # a batched call advances the healthy simulations and names the diverged ones
    calm = FIGNetDynamics(zero_simulator())
    datas = [mujoco.MjData(push_model) for _ in range(3)]
    for x in datas:
        mujoco.mj_forward(push_model, x)
    datas[1].qvel[0] = 1e3  # runaway speed
    datas[2].qpos[0] = np.nan  # non-finite state
    with pytest.raises(DivergenceError) as err:
        calm.step_many(push_model, datas, 10)
    assert err.value.indices == (1, 2)
    assert "max_speed" in err.value.reasons[0] and "non-finite" in err.value.reasons[1]
    assert datas[0].time == pytest.approx(0.02) and datas[1].time == 0.0
    # a rollout marks the diverged rows NaN and keeps the others
    nstate = mujoco.mj_stateSize(push_model, STATE_SPEC)
    init = np.zeros((2, nstate))
    for i in range(2):
        mujoco.mj_getState(push_model, datas[0], init[i], STATE_SPEC)
    init[1, 1 + push_model.nq] = 1e3  # qvel[0] of row 1
    out = calm.rollout(push_model, init, _tip_path(push_model, 3)[None], frame_skip=10)
    assert np.isfinite(out[0]).all() and np.isnan(out[1]).all()


def test_mujoco_instability_is_reported(tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # MuJoCo logs the warning to MUJOCO_LOG.TXT in the working dir
    xml = """<mujoco><option timestep="0.01"/><worldbody><geom type="plane" size="1 1 .1"/>
      <body pos="0 0 .1"><freejoint/><geom type="box" size=".05 .05 .05" mass="1e-9"/></body>
      </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(model)
    d.qvel[:3] = 1e30
    with pytest.raises(DivergenceError, match="MuJoCo reported"):
        MujocoDynamics().step(model, d)


def test_scene_type_and_user_dynamics(push_model: mujoco.MjModel) -> None:
    dyn = FIGNetDynamics(zero_simulator("toss"))
    with pytest.raises(ValueError, match="trained on 'toss' scenes, not 'push'"):
        dyn.validate(push_model, 10, "push")
    FIGNetDynamics(zero_simulator("push")).validate(push_model, 10, "push")

    class Frozen(DynamicsBase):
        """A user's dynamics: only step; the rest comes from DynamicsBase."""

        def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
            data.time += nstep * model.opt.timestep
            mujoco.mj_forward(model, data)

    user = make_dynamics(Frozen())
    nstate = mujoco.mj_stateSize(push_model, STATE_SPEC)
    out = user.rollout(
        push_model, np.zeros((2, nstate)), _tip_path(push_model, 3)[None], frame_skip=5
    )
    np.testing.assert_allclose(out[:, :, 0], [[0.01, 0.02, 0.03]] * 2)


def test_fignet_bfloat16_precision_follows_float32() -> None:
    """The opt-in bf16 network on the shipped push model: a 0.5 s push stays within a few
    millimetres of the float32 rollout (median under 1 mm, 9 in 10 under 5 mm; the largest qpos
    coordinate, quaternions included), and is not bit-identical to it (the bf16 network did run).
    Over 500 pushes of 5 objects (experiments/README.md, "bfloat16"): median 0.39 mm, 90th
    percentile 2.1 mm, max 14 (push-pyramidal: 0.61, 2.15, 10.8); here 0.46 mm, max 13."""
    push_model = mujoco.MjModel.from_xml_string(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    d = mujoco.MjData(push_model)
    nstate = mujoco.mj_stateSize(push_model, STATE_SPEC)
    B = 48  # enough nodes (30 each) for the bf16 network (LOW_PRECISION_MIN_NODES)
    init = np.zeros((B, nstate))
    for i in range(B):
        mujoco.mj_resetData(push_model, d)
        d.qpos[1] = 0.001 * i
        mujoco.mj_getState(push_model, d, init[i], STATE_SPEC)
    control = np.stack([_tip_path(push_model, 25, speed=0.1)] * B)
    f32 = FIGNetDynamics("push")
    bf16 = FIGNetDynamics("push", precision="bfloat16")
    assert bf16.simulator.inference_dtype == torch.bfloat16
    a = f32.rollout(push_model, init, control, frame_skip=10)
    b = bf16.rollout(push_model, init, control, frame_skip=10)
    qpos = slice(1, 1 + push_model.nq)  # the state is (time, qpos, qvel, ...)
    assert np.abs(a[:, -1, qpos] - init[:, qpos]).max() > 0.01  # the object was pushed
    # [B]: the worst qpos coordinate (m, or quaternion units: 0.01 is about 1 deg) and step
    gap = np.abs(a[..., qpos] - b[..., qpos]).max(axis=(1, 2))
    assert 0 < np.median(gap) < 1e-3 and np.percentile(gap, 90) < 5e-3, np.percentile(gap, [50, 90])
    with pytest.raises(ValueError, match="precision must be one of"):
        FIGNetDynamics("push", precision="float16")
