"""The compiled runtime library: its C entry points, typed once, and the FbSystem struct.

One library per install (``generated/runtime`` + ``generated/kernels``, compiled on first
use into the cache) holds the integrator, the phase machine's fixed point, the assembled
particles formulation and the element kernels.  Models reach it as an ``FbSystem``
(``generated/runtime/fb_runtime.h``): sizes, a data pointer and five functions.
"""

from __future__ import annotations

import ctypes
import functools

from . import cbuild

_ptr, _int, _double, _long = ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_long


class FbSystem(ctypes.Structure):
    """``struct FbSystem`` of fb_runtime.h (filled by C: ``fb_asm_system`` or a model's ``fb_system``)."""

    _fields_ = [
        ("nq", _int), ("nu", _int), ("nc", _int), ("ny", _int), ("n_particles", _int), ("dim", _int),
        ("data", _ptr), ("rhs", _ptr), ("gaps", _ptr), ("contact_state", _ptr), ("impact", _ptr),
        ("outputs", _ptr), ("project", _ptr),
    ]  # fmt: skip


#: name -> (restype, argtypes) of every entry point the runtime library exports.
SIGNATURES = {
    "fb_work_new": (_ptr, [_int, _int]),
    "fb_work_free": (None, [_ptr]),
    "fb_integrate": (_int, [_ptr, _ptr, _int, _double, _ptr, _double, _ptr, _ptr, _ptr, _ptr, _double, _double,
                            _double, _ptr, _int, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _double]),
    "fb_resolve": (_int, [_ptr, _ptr, _double, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _double, _ptr, _ptr,
                          _int, _double, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_trajectory": (_int, [_ptr, _ptr, _long, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_time_rhs": (_double, [_ptr, _ptr, _int, _ptr, _ptr, _ptr]),
    "fb_asm_new": (_ptr, [_int, _int, _int, _int, _ptr, _ptr]),
    "fb_asm_free": (None, [_ptr]),
    "fb_asm_bind": (None, [_ptr, _ptr]),
    "fb_asm_system": (None, [_ptr, _ptr]),
    "fb_asm_link_jacobians": (None, [_ptr, _ptr, _ptr]),
    "fb_sys_rhs": (_int, [_ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_gaps": (None, [_ptr, _ptr, _ptr]),
    "fb_sys_contact_state": (_int, [_ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_impact": (_int, [_ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_outputs": (None, [_ptr, _ptr, _ptr, _ptr, _ptr]),
}


@functools.cache
def library() -> ctypes.CDLL:
    """The runtime library, compiled on first use, with every entry point typed."""
    lib = ctypes.CDLL(str(cbuild.runtime_library_path()))
    for name, (restype, argtypes) in SIGNATURES.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    return lib


class Work:
    """The C work buffers of one run (``fb_work_new``), freed with this object."""

    def __init__(self, ny: int, nc: int) -> None:
        self._lib = library()
        self.address = self._lib.fb_work_new(ny, nc)
        if not self.address:
            raise MemoryError(f"cannot allocate the integrator's work buffers for {ny} states and {nc} contacts")

    def __del__(self) -> None:
        if getattr(self, "address", None):
            self._lib.fb_work_free(self.address)
            self.address = None
