"""The Python API as a script uses it: flexbody.simulate's options, a model passed in, scene
tables built with NumPy values, results compared.

References: the README's and the docstrings' rules (each bad option one InputError naming
it, its value and the rule, before any work), and the same run made the documented way.
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.model import load_model

from .conftest import needs_cc


@pytest.fixture(scope="module")
def ball():
    return flexbody.load_scene("thesis_ball")


@pytest.mark.parametrize("options, says", [
    ({"rtol": "1e-6"}, "`rtol` = '1e-6': must be a number in [1e-14, 1)"),
    ({"atol": None, "rtol": True}, "`rtol` = True: must be a number in [1e-14, 1)"),
    ({"max_wall_time": "10"}, "`max_wall_time` = '10': must be a number of seconds > 0 (inf: no limit)"),
    ({"max_wall_time": 0}, "`max_wall_time` = 0: must be a number of seconds > 0"),
    ({"max_wall_time": float("nan")}, "`max_wall_time` = nan: must be a number of seconds > 0"),
    ({"max_events": 0}, "`max_events` = 0: must be an integer >= 1"),
    ({"progress": 5}, "`progress` = 5: must be a callable progress(t, t_end, n_events), or None"),
])
def test_a_bad_option_is_one_clear_error_before_any_work(ball, options, says):
    """A helper's script met bare TypeErrors from deep in the driver (a string rtol, a string
    wall time), runs that ended at once (max_wall_time 0, max_events 0), a wall time of nan
    read as no limit, and a progress of 5 failing mid-run."""
    with pytest.raises(flexbody.InputError) as info:
        flexbody.simulate(ball, t_end=0.1, **options)
    assert says in str(info.value)


@pytest.mark.parametrize("scene", [None, 42, [1, 2]])
def test_a_scene_that_is_no_scene_is_one_clear_error(scene):
    with pytest.raises(flexbody.InputError, match="must be a"):
        flexbody.simulate(scene)


@needs_cc
def test_a_model_given_decides_the_backend_and_asking_for_another_is_refused(ball):
    """A NumPy model alone runs on NumPy (it was refused: the default method was the C
    loop's), and a backend or formulation other than the model's is an error, not ignored."""
    numpy_model = load_model(ball, backend="numpy")
    r = flexbody.simulate(ball, model=numpy_model, t_end=0.3)
    assert r.success and r.stats["backend"] == "numpy" and r.stats["method"] == "RK45"
    same = flexbody.simulate(ball, backend="numpy", t_end=0.3)
    np.testing.assert_array_equal(r.positions, same.positions)
    c_model = load_model(ball)
    for option, value in (("backend", "numpy"), ("formulation", "floating")):
        with pytest.raises(flexbody.InputError, match=f"`{option}` = '{value}': the model given is {option} "):
            flexbody.simulate(ball, model=c_model, t_end=0.3, **{option: value})
    rigid = flexbody.load_scene("rigid_bar")  # rigid bodies alone run on frames T whichever is asked
    assert flexbody.simulate(rigid, model=load_model(rigid), formulation="particles").success


def test_numpy_values_in_a_scene_table_read_as_toml_would_give_them():
    """A table built from NumPy values: an int64 count, a float64 radius, an array position
    and a bool_ (refused before as not an integer, not a list)."""
    table = {"bodies": [{"name": "b", "shape": "ring", "count": np.int64(12), "radius": np.float64(0.1),
                         "center": np.bool_(True), "mass": 0.05, "stiffness": 2000.0, "damping": 0.5,
                         "position": np.array([0.0, 0.5])}], "simulation": {"t_end": 0.1}}
    plain = {"bodies": [{"name": "b", "shape": "ring", "count": 12, "radius": 0.1, "center": True, "mass": 0.05,
                         "stiffness": 2000.0, "damping": 0.5, "position": [0.0, 0.5]}], "simulation": {"t_end": 0.1}}
    a, b = flexbody.load_scene(table), flexbody.load_scene(plain)
    assert a.topology().digest("particles") == b.topology().digest("particles")
    np.testing.assert_array_equal(a.initial_positions(), b.initial_positions())
    assert a.bodies[0].position == b.bodies[0].position == (0.0, 0.5)


def test_results_compare_by_identity_not_by_their_arrays(ball):
    """`result == loaded` raised numpy's ambiguous truth value; a result equals only itself
    (compare arrays with numpy)."""
    a = flexbody.simulate(ball, t_end=0.05, output_dt=0.01)
    b = flexbody.simulate(ball, t_end=0.05, output_dt=0.01)
    assert a == a and a != b
    np.testing.assert_array_equal(a.positions, b.positions)
