"""Shared fixtures: small scenes built in code, and their models in both backends."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

import flexbody
from flexbody.model import load_derived_model as load_model  # the whole-scene derivation

HAS_CC = shutil.which(os.environ.get("CC", "cc")) is not None
BACKENDS = ["numpy", "c"] if HAS_CC else ["numpy"]
#: For tests that run the default backend (c) or a compiled method: skipped cleanly without a compiler.
needs_cc = pytest.mark.skipif(not HAS_CC, reason="no C compiler: the default backend is compiled C")


def reference_table(name: str) -> dict:
    """The scene table ``tests/reference/<name>.json`` (a fuzz's scene kept as a test), a
    mesh file it names (``"file"``) read from the package's bundled scenes, wherever the
    package and the checkout are."""
    import json
    from pathlib import Path

    table = json.loads((Path(__file__).parent / "reference" / f"{name}.json").read_text())
    for entry in table.get("bodies", []):
        if "file" in entry:
            entry["file"] = str(Path(flexbody.__file__).parent / "scenes" / Path(entry["file"]).name)
    return table


def body(**overrides):
    """A body table with every required field; override any of them."""
    table = {
        "name": "b",
        "particles": [[-0.1, 0.0], [0.1, 0.0]],
        "links": [[0, 1]],
        "mass": 0.05,
        "stiffness": 2000.0,
        "damping": 0.5,
        "damper": "relative",
        "position": [0.0, 0.3],
    }
    table.update(overrides)
    return {k: v for k, v in table.items() if v is not None}  # None removes a key


def scene_table(*bodies, **top):
    """A scene table (mapping) with the given bodies and a 1 s simulation."""
    table = {"bodies": list(bodies) or [body()], "simulation": {"t_end": 1.0}}
    table.update(top)
    return table


def make_scene(*bodies, **top) -> flexbody.Scene:
    return flexbody.load_scene(scene_table(*bodies, **top))


@pytest.fixture(scope="session")
def ball():
    return flexbody.load_scene("thesis_ball")


@pytest.fixture(scope="session")
def ball_models(ball):
    """{(formulation, backend): Model} for the thesis ball."""
    return {(f, b): load_model(ball, backend=b, formulation=f) for f in ("particles", "floating") for b in BACKENDS}


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
