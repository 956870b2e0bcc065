"""One MuJoCo-parameters type: the shipped fit, the env, the old env format and the JSON form."""

from __future__ import annotations

import json
import warnings
from dataclasses import fields
from pathlib import Path

import mujoco
import numpy as np
import pytest

from fignet_gym.dynamics.contact_params import ContactParams
from fignet_gym.envs.cube_toss import (
    DATA_DT,
    CubeTossEnv,
    cube_toss_xml,
    fitted_mujoco_path,
    mujoco_parameters,
)

#: The shipped fit as it was written before the one type (``friction`` triple, ``timestep``).
OLD_FIT = Path(__file__).parent / "data" / "cube-real.mujoco.v0.json"


def _arrays(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    """Every numeric array of a compiled model and of its options, by name."""
    out = {}
    for obj, prefix in ((model, ""), (model.opt, "opt.")):
        for name in dir(obj):
            if name.startswith("_"):
                continue
            value = getattr(obj, name)
            if isinstance(value, (np.ndarray, int, float)) and not isinstance(value, bool):
                out[prefix + name] = np.asarray(value)
    return out


def test_env_from_the_old_and_the_reshipped_fit_is_identical() -> None:
    with pytest.warns(FutureWarning, match="old CubeToss-v0 format"):
        old = CubeTossEnv(dynamics="mujoco", mujoco_params=str(OLD_FIT))
    new = CubeTossEnv(dynamics="mujoco", mujoco_params="fitted")
    a, b = _arrays(old.model), _arrays(new.model)
    assert a.keys() == b.keys() and len(a) > 50
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    # Independent truth: the old file's own numbers are what MuJoCo runs (to the 9 digits of MJCF).
    raw = json.loads(OLD_FIT.read_text())
    close = {"rtol": 1e-8}
    np.testing.assert_allclose(new.model.geom_friction, [raw["friction"]] * 2, **close)
    np.testing.assert_allclose(new.model.geom_solref, [[raw["timeconst"], raw["dampratio"]]] * 2, **close)
    np.testing.assert_allclose([new.model.opt.timestep, new.model.opt.gravity[2], new.model.opt.impratio],
                               [raw["timestep"], raw["gravity"], raw["impratio"]], **close)
    assert new.model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert new.mujoco_params.source == json.loads(fitted_mujoco_path().read_text())["source"]


def test_shipped_fit_is_in_the_one_format() -> None:
    raw = json.loads(fitted_mujoco_path().read_text())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no conversion on the way
        params = ContactParams.load(fitted_mujoco_path())
    assert params.to_json() == raw
    assert params.substeps == 8 and params.cone == "elliptic"


def test_old_format_needs_the_data_step_and_says_how_to_convert() -> None:
    raw = json.loads(OLD_FIT.read_text())
    with pytest.raises(ValueError, match="old CubeToss-v0 format; write 'substeps'") as err:
        ContactParams.from_json(raw)
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="does not divide"):
        ContactParams.from_json({**raw, "timestep": DATA_DT / 7.5}, DATA_DT)
    with pytest.warns(FutureWarning):
        p = ContactParams.from_json(raw, DATA_DT)
    assert (p.friction, p.torsional, p.rolling) == tuple(raw["friction"])
    assert p.substeps * raw["timestep"] == pytest.approx(DATA_DT, rel=1e-12)


def test_json_round_trip_and_unknown_keys() -> None:
    p = ContactParams(friction=0.3, torsional=0.01, timeconst=0.01, dampratio=0.9, cone="elliptic",
                      impratio=3.0, gravity=-9.7, substeps=5, integrator="RK4", source="test")
    assert ContactParams.from_json(p.to_json()) == p
    assert set(ContactParams().to_json()) == set()
    with pytest.raises(ValueError, match=r"fit.json: unknown contact parameters \['frction'\]"):
        ContactParams.from_json({"frction": 0.2}, where="fit.json")
    with pytest.raises(ValueError, match="cone must be one of"):
        ContactParams(cone="round")


def test_filled_takes_unset_fields_from_the_base() -> None:
    base = mujoco_parameters("nominal")
    p = ContactParams(friction=0.5, substeps=2).filled(base)
    assert p.friction == 0.5 and p.substeps == 2
    assert all(getattr(p, f.name) == getattr(base, f.name) for f in fields(ContactParams)
               if f.name not in ("friction", "substeps"))
    # The env refuses what the cube scene cannot apply, rather than ignoring it.
    with pytest.raises(ValueError, match="does not use"):
        mujoco_parameters({"integrator": "RK4"})
    m = mujoco.MjModel.from_xml_string(cube_toss_xml(p))
    assert m.opt.timestep == pytest.approx(DATA_DT / 2) and m.geom_friction[0, 0] == 0.5
