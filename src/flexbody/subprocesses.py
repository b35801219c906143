"""Child Python processes that end with their parent.

SymPy runs in a child process (the runtime never imports it).  A derivation can take
minutes, and the user may kill ``flexbody run`` meanwhile: the child must not live on.

* The child runs in its own process group, and the parent kills that group whenever it
  stops waiting for it (an exception, Ctrl-C, a timeout).
* On Linux the child also asks the kernel to kill it when its parent dies
  (``prctl(PR_SET_DEATHSIG, SIGKILL)``), which covers a parent killed by SIGKILL, where
  no ``finally`` runs.  It does so itself, first thing, in a small launcher (no
  ``preexec_fn``, which is unsafe when the parent has threads).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

#: Run in the child: ask to die with the parent, check the parent is still the one that
#: started us (it may have died before the request), then run the module as ``-m`` would.
_LAUNCHER = """\
import ctypes, os, runpy, signal, sys
try:
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)  # 1 = PR_SET_DEATHSIG (Linux)
except (OSError, AttributeError):
    pass
if os.getppid() != int(sys.argv[1]):
    sys.exit(1)
del sys.argv[:2]
runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
"""


def tied_command(module: str, args: list[str]) -> list[str]:
    """The command line that runs ``python -m module args`` as a child tied to this process."""
    return [sys.executable, "-c", _LAUNCHER, str(os.getpid()), module, *args]


def run_tied(module: str, args: list[str], *, env: dict[str, str] | None = None,
             capture: bool = False) -> subprocess.CompletedProcess:
    """Run ``python -m module args`` and wait for it; the child never outlives this call.

    Parameters
    ----------
    module : str
        A module or package with ``__main__``, as for ``python -m``.
    args : list of str
    env : dict, optional
        The child's environment (default: this process's).
    capture : bool
        Capture standard output and error as text (else they go to this process's).

    Returns
    -------
    subprocess.CompletedProcess
    """
    pipe = subprocess.PIPE if capture else None
    child = subprocess.Popen(tied_command(module, args), env=env, stdout=pipe, stderr=pipe, text=True,
                             start_new_session=True)  # its own group: kill it and anything it starts
    try:
        stdout, stderr = child.communicate()
    except BaseException:
        kill_group(child)
        raise
    return subprocess.CompletedProcess(child.args, child.returncode, stdout, stderr)


def kill_group(child: subprocess.Popen) -> None:
    """Kill ``child``'s process group (it leads one: ``start_new_session``) and reap it."""
    try:
        os.killpg(child.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    child.wait()
