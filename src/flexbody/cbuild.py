"""Compile a generated C model into a shared library, cached by the hash of its source.

The key covers the C source, its header, the compiler, the flags and the CPU, so a
changed model, toolchain or machine never reuses a stale library.  A compiler error is
raised with the compiler's full output.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import subprocess
from pathlib import Path

from .paths import cache_root, staged_file

FLAGS = ("-O3", "-shared", "-fPIC", "-std=c99")  # -O3: the integrator's vector loops vectorise
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


@functools.cache
def flags(cc: str) -> tuple[str, ...]:
    """The compile flags: FLAGS, plus NATIVE if ``cc`` accepts it."""
    probe = subprocess.run([cc, NATIVE, "-x", "c", "-E", os.devnull], capture_output=True, check=False)
    return FLAGS + (NATIVE,) if probe.returncode == 0 else FLAGS


@functools.cache
def _cpu_identity() -> str:
    """Model name and feature flags of this CPU (what -march=native compiles for)."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    wanted = [line for line in lines if line.split(":")[0].strip() in ("model name", "flags", "Features")]
    return "\n".join(dict.fromkeys(wanted)) or f"{platform.machine()} {platform.processor()}"


def library_path(model_dir: Path) -> Path:
    """Compile ``model_dir/*.c`` (model and integrator) if needed; return the cached library."""
    model_dir = Path(model_dir)
    cc = compiler()
    sources = sorted(model_dir.glob("*.c"))
    source = b"".join(path.read_bytes() for path in sources + [model_dir / "model.h"])
    options = flags(cc)
    identity = "\n".join([_compiler_identity(cc), " ".join(options), _cpu_identity()])
    key = hashlib.sha256(source + identity.encode()).hexdigest()[:24]
    target = cache_root() / "lib" / f"{key}.so"
    if target.exists():
        return target
    with staged_file(target, suffix=".so") as tmp:  # a concurrent build never sees a half-written library
        command = [cc, *options, "-I", str(model_dir), "-o", str(tmp), *map(str, sources), "-lm"]
        run = subprocess.run(command, capture_output=True, text=True, check=False)
        if run.returncode != 0:
            raise CompilationError(
                f"compiling {model_dir}/*.c failed (exit {run.returncode}):\n$ {' '.join(command)}\n"
                f"{run.stdout}{run.stderr}"
            )
    return target
