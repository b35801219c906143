"""Compile a generated C model into a shared library, cached by the hash of its source.

The key covers the C source, its header, the compiler, the flags and the CPU, so a
changed model, toolchain or machine never reuses a stale library.  A compiler error is
raised with the compiler's full output.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from .paths import cache_root, generated_root, staged_file

#: -O3: the integrator's vector loops vectorise.  -fno-math-errno: sqrt need not set errno, so
#: the link kernels' loop over a block of links vectorises (their square roots); the values are
#: the same (sqrt is correctly rounded either way).
FLAGS = ("-O3", "-fno-math-errno", "-shared", "-fPIC", "-std=c99")
#: Used when the compiler accepts it: wider vector loops (measured ~10 % off the compiled
#: integrator); the library then fits only this kind of CPU, which the cache key names.
NATIVE = "-march=native"


class CompilationError(RuntimeError):
    """The C compiler failed or is missing; the message carries its full output."""


def compiler() -> str:
    cc = os.environ.get("CC", "cc")
    if shutil.which(cc) is None:
        raise CompilationError(
            f"no C compiler found (looked for `{cc}`; set CC to choose one). "
            "Install one (e.g. `apt-get install gcc`) or use backend='numpy'."
        )
    return cc


@functools.cache
def _compiler_identity(cc: str) -> str:
    run = subprocess.run([cc, "--version"], capture_output=True, text=True, check=False)
    return run.stdout.splitlines()[0] if run.stdout else cc


#: Used when the compiler can build and link it: the assembled right-hand side of a large
#: body splits its link loop over threads (OpenMP; without it the same code runs on one).
OPENMP = "-fopenmp"
_OPENMP_PROBE = "#include <omp.h>\nint fb_probe(void) { return omp_get_max_threads(); }\n"


@functools.cache
def flags(cc: str) -> tuple[str, ...]:
    """The compile flags: FLAGS, plus NATIVE and OPENMP where ``cc`` accepts them."""
    extra = []
    probe = subprocess.run([cc, NATIVE, "-x", "c", "-E", os.devnull], capture_output=True, check=False)
    if probe.returncode == 0:
        extra.append(NATIVE)
    with tempfile.TemporaryDirectory() as tmp:
        probe = subprocess.run([cc, OPENMP, "-shared", "-fPIC", "-x", "c", "-", "-o", str(Path(tmp) / "probe.so")],
                               input=_OPENMP_PROBE, capture_output=True, text=True, check=False)
    if probe.returncode == 0:
        extra.append(OPENMP)
    return FLAGS + tuple(extra)


@functools.cache
def _cpu_identity() -> str:
    """Model name and feature flags of this CPU (what -march=native compiles for)."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    wanted = [line for line in lines if line.split(":")[0].strip() in ("model name", "flags", "Features")]
    return "\n".join(dict.fromkeys(wanted)) or f"{platform.machine()} {platform.processor()}"


def build(sources: list[Path], include_dirs: list[Path], what: str, announce: str = "") -> Path:
    """Compile ``sources`` into one shared library if needed; return the cached library.

    The cache key covers every source and every header in ``include_dirs``, so a library is
    rebuilt exactly when something it is built from changed.  ``announce`` is printed to
    stderr before a compile (first use can take seconds).
    """
    cc = compiler()
    headers = [h for d in include_dirs for h in sorted(Path(d).glob("*.h"))]
    source = b"".join(p.name.encode() + b"\0" + p.read_bytes() for p in list(sources) + headers)
    # The key names the compiler (command and version) and every flag it may get, not the
    # flags it accepts: those follow from the compiler, and probing them costs a compile
    # (~0.07 s), paid only when something is built.
    wanted = " ".join(FLAGS + (NATIVE, OPENMP))
    identity = "\n".join([cc, _compiler_identity(cc), wanted, _cpu_identity()])
    key = hashlib.sha256(source + identity.encode()).hexdigest()[:24]
    target = cache_root() / "lib" / f"{key}.so"
    if target.exists():
        return target
    options = flags(cc)
    if announce:
        print(announce, file=sys.stderr, flush=True)
    includes = [arg for d in include_dirs for arg in ("-I", str(d))]
    with staged_file(target, suffix=".so") as tmp:  # a concurrent build never sees a half-written library
        command = [cc, *options, *includes, "-o", str(tmp), *map(str, sources), "-lm"]
        run = subprocess.run(command, capture_output=True, text=True, check=False)
        if run.returncode != 0:
            raise CompilationError(
                f"compiling {what} failed (exit {run.returncode}):\n$ {' '.join(command)}\n{run.stdout}{run.stderr}"
            )
    return target


def load(path: Path) -> ctypes.CDLL:
    """Load a compiled library.  OpenMP's threads then wait asleep, not spinning, unless
    OMP_WAIT_POLICY says otherwise: on a shared machine a spinning thread holds the core its
    partner needs (the 10 000-particle drop ran 2.3x slower than on one thread beside one
    busy process; asleep it ran as fast as one thread, and 1.3x faster on an idle machine)."""
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")  # read when libgomp loads
    return ctypes.CDLL(str(path))


def library_path(model_dir: Path) -> Path:
    """Compile a whole-scene model (``model_dir/model.c``, against the runtime's header)."""
    model_dir = Path(model_dir)
    return build(sorted(model_dir.glob("*.c")), [model_dir, runtime_dir()], f"{model_dir}/*.c")


def runtime_dir() -> Path:
    return generated_root() / "runtime"


def kernels_dir() -> Path:
    return generated_root() / "kernels"


def runtime_library_path() -> Path:
    """Compile the model-independent runtime (integrator, phase machine, assembly) with the
    element kernels into one library, once per install (cached by content)."""
    sources = sorted(runtime_dir().glob("*.c")) + [kernels_dir() / "kernels.c"]
    return build(sources, [runtime_dir(), kernels_dir()], "the flexbody runtime (generated/runtime, generated/kernels)",
                 announce="flexbody: compiling the runtime library once for this machine (usually 5-15 s) ...")
