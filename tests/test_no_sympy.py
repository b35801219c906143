"""The runtime without SymPy: simulate, save, load and the CLI, with ``sympy`` made unimportable."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from .conftest import HAS_CC

# Runs first in the child: importing sympy or jinja2 raises, as if they were not installed (the
# derivation package imports sympy first thing, so it cannot be imported either).
BLOCKER = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('sympy', 'jinja2'):
            raise ModuleNotFoundError(f'{name} is blocked: the runtime must not import it')
        return None
sys.meta_path.insert(0, _Block())
"""


def run_blocked(code: str, tmp_path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCKER + code], capture_output=True, text=True, cwd=tmp_path,
                          env=dict(os.environ))


def test_the_blocker_blocks(tmp_path):
    run = run_blocked("import sympy\n", tmp_path)
    assert run.returncode != 0 and "sympy is blocked" in run.stderr


@pytest.mark.parametrize("backend", ["numpy", "c"] if HAS_CC else ["numpy"])
def test_simulate_save_and_load_without_sympy(tmp_path, backend):
    method = "dopri5" if backend == "c" else "RK45"
    code = f"""
import flexbody
r = flexbody.simulate('dumbbell', backend='{backend}', method='{method}', t_end=0.4)
assert r.success, r.message
assert r.stats['impacts'] == 2, r.stats
out = r.save('run')
back = flexbody.load_result(out)
assert back.positions.shape == r.positions.shape
bad = [k for k in sys.modules if k.split('.')[0] in ('sympy', 'jinja2', 'derivation')]
assert not bad, bad
print('ok')
"""
    run = run_blocked(code, tmp_path)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr


def test_cli_run_and_show_without_sympy(tmp_path):
    code = """
from flexbody.cli import main
assert main(['run', 'dumbbell', '--out', 'out', '--t-end', '0.4', '--quiet', '--backend', 'numpy', '--no-figures']) == 0
assert main(['show', 'dumbbell', '--formulation', 'floating']) == 0
assert main(['show', 'dumbbell', '--raw', '--latex']) == 0
"""
    run = run_blocked(code, tmp_path)
    assert run.returncode == 0, run.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "success" and summary["impacts"] == 2
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"result.npz", "summary.json"}
    assert "[vX0]" in run.stdout and "Raw equations (LaTeX)" in run.stdout
