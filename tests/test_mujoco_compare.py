"""The optional MuJoCo side-by-side model (skipped unless ``flexbody[mujoco]`` is installed)."""

from __future__ import annotations

import numpy as np
import pytest

import flexbody

from .conftest import needs_cc

mujoco = pytest.importorskip("mujoco")
pytestmark = needs_cc  # flexbody's side runs the default (compiled) backend


def test_mujoco_free_flight_converges_to_flexbody_at_first_order():
    """Before the first impact both simulate the same physics: MuJoCo's (first-order)
    integrator approaches flexbody's solution, halving its error with its step."""
    from flexbody.mujoco_compare import mjcf, run

    text = mjcf(flexbody.load_scene("thesis_ball"), 1e-4)
    assert text.count("<body ") == 23 and text.count("<spatial ") == 44
    scene = flexbody.load_scene({**_table(), "simulation": {"t_end": 0.25, "output_dt": 1e-4}})
    ours = flexbody.simulate(scene, method="dop853", rtol=1e-10, atol=1e-13)
    errors = []
    for dt in (2e-4, 1e-4):
        m = run(scene, dt, repeats=1)
        ref = np.array([np.interp(m["t"], ours.t, ours.positions[:, i, 1]) for i in range(23)]).T
        errors.append(np.abs(m["heights"] - ref).max())
    assert errors[1] < 1e-3
    assert 1.8 < errors[0] / errors[1] < 2.2


def test_mujoco_contact_is_soft_and_flexbody_contact_is_not():
    from flexbody.mujoco_compare import run

    scene = flexbody.load_scene({**_table(), "simulation": {"t_end": 0.4, "output_dt": 1e-3}})
    m = run(scene, 1e-3, repeats=1)
    ours = flexbody.simulate(scene)
    assert m["max_penetration_m"] > 1e-4  # MuJoCo's soft contact lets the ball sink in
    assert ours.stats["max_penetration_m"] < 1e-11  # flexbody's constraint does not


def _table():
    import tomllib
    from pathlib import Path

    return tomllib.loads(Path(flexbody.load_scene("thesis_ball").source).read_text())
