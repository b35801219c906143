"""Generated code: fresh, loadable without SymPy, compiled with clear errors; the CLI around it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from flexbody import cbuild
from flexbody.cli import main
from flexbody.paths import generated_root
from flexbody.scene import bundled_scenes

from .conftest import HAS_CC


#: Bundled scenes whose whole-scene models are committed, and how many (the 3D ones run
#: assembled only; a scene with rigid bodies has its floating model only).
COMMITTED = {s: n for s in bundled_scenes()
             if (n := sum((generated_root() / f"{s}_{f}").is_dir() for f in ("particles", "floating")))}


@pytest.mark.parametrize("scene", [pytest.param(s, marks=pytest.mark.slow) if s == "thesis_ball" else s
                                   for s in COMMITTED])  # the thesis ball's floating model takes minutes
def test_generated_code_is_fresh(scene):
    """Regenerate in memory and compare byte for byte; fails with a diff when stale."""
    run = subprocess.run([sys.executable, "-m", "flexbody.cli", "derive", scene, "--check"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    assert run.stdout.count("fresh") == COMMITTED[scene]


def test_generated_runtime_and_kernels_are_fresh():
    """The element kernels and the runtime, rendered again in memory, equal what is committed."""
    run = subprocess.run([sys.executable, "-m", "flexbody.cli", "derive", "--runtime", "--check"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    assert run.stdout.count("fresh") == 2


@pytest.mark.parametrize("edited, changes", [("elements.py", False), ("runtime.py", False), ("mechanics.py", True)])
def test_editing_a_derivation_module_marks_stale_only_what_it_generates(tmp_path, edited, changes):
    """Whole-scene model digests depend on the whole-scene generator only (run from a copy
    of derivation/ with one file edited): editing the element
    kernels' or the runtime's module leaves every cached model valid; editing Kane's does not."""
    import derivation

    copy = tmp_path / "derivation"
    shutil.copytree(Path(derivation.__file__).parent, copy, ignore=shutil.ignore_patterns("__pycache__"))
    code = "from flexbody.topology import generator_fingerprint; print(generator_fingerprint())"

    def fingerprint():
        env = dict(os.environ, PYTHONPATH=str(tmp_path))
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path,
                              check=True).stdout.strip()

    before = fingerprint()
    with open(copy / edited, "a") as handle:
        handle.write("\n# an edit\n")
    assert (fingerprint() != before) == changes


def test_check_detects_a_stale_file(tmp_path):
    target = tmp_path / "dumbbell_particles"
    shutil.copytree(generated_root() / "dumbbell_particles", target)
    shutil.copytree(generated_root() / "dumbbell_floating", tmp_path / "dumbbell_floating")
    (target / "model.py").write_text((target / "model.py").read_text().replace("w0", "w0 ", 1))
    run = subprocess.run([sys.executable, "-m", "flexbody.cli", "derive", "dumbbell", "--check", "--out", str(tmp_path)],
                         capture_output=True, text=True)
    assert run.returncode == 1
    assert "model.py: stale" in run.stdout and "STALE" in run.stdout


def test_runtime_never_imports_sympy():
    code = (
        "import sys, numpy as np, flexbody\n"
        "from flexbody.model import load_model\n"
        "from flexbody.state import initial_coordinates\n"
        "s = flexbody.load_scene('thesis_ball')\n"
        f"for backend in {['numpy', 'c'] if HAS_CC else ['numpy']}:\n"
        "    m = load_model(s, backend=backend)\n"
        "    q, u = initial_coordinates(s, m)\n"
        "    m.rhs(np.concatenate([q, u, [0, 0]]), m.parameters(s), np.zeros(m.n_contacts, int), np.zeros(m.n_contacts))\n"
        "bad = [k for k in sys.modules if k.split('.')[0] in ('sympy', 'jinja2', 'derivation')]\n"
        "assert not bad, bad\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_compiler_error_is_shown_in_full(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXBODY_CACHE", str(tmp_path / "cache"))
    broken = tmp_path / "model"
    shutil.copytree(generated_root() / "dumbbell_particles", broken)
    (broken / "model.c").write_text((broken / "model.c").read_text() + "\nthis is not C;\n")
    with pytest.raises(cbuild.CompilationError) as info:
        cbuild.library_path(broken)
    message = str(info.value)
    assert "model.c" in message and "error" in message and "this is not C" in message
    assert not list((tmp_path / "cache" / "lib").glob("*.so"))  # nothing half-built left behind


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_compiler_without_native_tuning_or_openmp_still_builds(tmp_path, monkeypatch):
    """A compiler that rejects -march=native and -fopenmp gets the portable flags, and a
    library of its own."""
    fussy = tmp_path / "fussy-cc"
    fussy.write_text('#!/bin/sh\nfor a in "$@"; do case "$a" in -march=native|-fopenmp) exit 1;; esac; done\n'
                     'exec cc "$@"\n')
    fussy.chmod(0o755)
    monkeypatch.setenv("FLEXBODY_CACHE", str(tmp_path / "cache"))
    assert cbuild.flags(str(fussy)) == cbuild.FLAGS
    monkeypatch.setenv("CC", str(fussy))
    portable = cbuild.library_path(generated_root() / "dumbbell_particles")
    assert cbuild.runtime_library_path().exists()  # its OpenMP pragmas ignored, omp.h not included
    monkeypatch.setenv("CC", "cc")
    native = cbuild.library_path(generated_root() / "dumbbell_particles")
    assert portable.exists() and native.exists() and portable != native
    assert cbuild.NATIVE in cbuild.flags("cc")


def test_missing_compiler_says_what_to_do(monkeypatch):
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    with pytest.raises(cbuild.CompilationError, match="backend='numpy'"):
        cbuild.compiler()


def test_scene_without_generated_model_is_derived_on_demand(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXBODY_CACHE", str(tmp_path))
    from flexbody.model import load_model

    from .conftest import body, make_scene

    scene = make_scene(body(particles=[[0, 0], [0.1, 0], [0, 0.1]], links=[[0, 1], [1, 2], [2, 0]]))
    model = load_model(scene, backend="numpy", formulation="floating")
    assert model.directory.parent == tmp_path / "models"
    assert (model.directory / "model.c").is_file() and model.nu == 6


@pytest.mark.parametrize("command", [[], ["run"], ["derive"], ["show"], ["bench"]])
def test_every_command_has_help(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([*command, "--help"])
    assert info.value.code == 0
    assert "usage: flexbody" in capsys.readouterr().out


@pytest.mark.parametrize("latex", [False, True])
def test_show_prints_the_equations(latex, capsys):
    assert main(["show", "dumbbell", "--formulation", "particles"] + (["--latex"] if latex else [])) == 0
    out = capsys.readouterr().out
    assert "k0" in out and "m0" in out
    if latex:
        assert "\\frac" in out or "\\sqrt" in out
    else:
        assert "[vx0]  m0*vx0' =" in out


def test_show_bad_scene_is_a_clear_error(capsys):
    assert main(["show", "no_such_scene"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and "Traceback" not in err


def test_generated_headers_name_template_source_and_command():
    folder = generated_root() / "thesis_ball_particles"
    for name, comment in (("model.py", "#"), ("model.c", "/*"), ("model.h", "/*"), ("eom.md", "<!--")):
        head = (folder / name).read_text().splitlines()[:3]
        assert head[0].startswith(comment) and f"template {name}.jinja" in head[0]
        assert "Source scene: thesis_ball" in head[1] and "flexbody derive thesis_ball" in head[2]
    assert not any(os.path.splitext(f)[1] in (".so", ".o") for f in os.listdir(folder))
