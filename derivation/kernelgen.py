"""Code generation of the element kernels: :mod:`derivation.elements` -> C and NumPy.

Each kernel gets its own CSE pass and is printed twice: a ``static inline`` C function in
``kernels.h`` (the assembler includes it, so the compiler inlines it into its loops), with
an exported batched wrapper in ``kernels.c`` for tests, and a NumPy function vectorised
over elements in ``kernels.py``.  Output is deterministic (no timestamps, fixed order).
"""

from __future__ import annotations

import hashlib
import json

import jinja2
import sympy as sp

from .codegen import environment
from .elements import DAMPERS, DIMENSIONS, Kernel, all_kernels
from .printers import CPrinter, PyPrinter

#: Rendered files of generated/kernels/: template -> file name.
FILES = {"kernels.h.jinja": "kernels.h", "kernels.c.jinja": "kernels.c", "kernels.py.jinja": "kernels.py"}
COMMAND = "flexbody derive --runtime"


def _kernel_context(kernel: Kernel) -> dict:
    names = list(kernel.outputs)
    flat = [e for name in names for e in kernel.outputs[name]]
    temporaries, reduced = sp.cse(flat, symbols=sp.numbered_symbols("w"), order="none")
    c_names = {s.name: f"{arg}[{i}]" for arg, symbols in kernel.inputs for i, s in enumerate(symbols)}
    c_printer, py_printer = CPrinter(c_names), PyPrinter()
    outputs, start = [], 0
    for name in names:
        matrix = kernel.outputs[name]
        values = reduced[start : start + len(matrix)]
        start += len(matrix)
        outputs.append({
            "name": name,
            "size": len(matrix),
            "shape": list(matrix.shape) if matrix.shape[1] > 1 else [matrix.shape[0]],
            "entries": [(k, c_printer.doprint(v), py_printer.doprint(v)) for k, v in enumerate(values)],
        })
    return {
        "name": kernel.name,
        "doc": kernel.doc,
        "inputs": [{"name": arg, "size": len(symbols), "symbols": [s.name for s in symbols]}
                   for arg, symbols in kernel.inputs],
        "temporaries": [(t.name, c_printer.doprint(e), py_printer.doprint(e)) for t, e in temporaries],
        "outputs": outputs,
        "ops": int(sp.count_ops([e for _, e in temporaries] + list(reduced))),
    }


def render_kernels() -> dict[str, str]:
    """Derive every element kernel and render ``generated/kernels/``; file name -> text."""
    kernels = [_kernel_context(k) for k in all_kernels()]
    env = environment()
    context = {"kernels": kernels, "command": COMMAND, "dimensions": DIMENSIONS, "dampers": DAMPERS}
    files = {out: env.get_template(t).render(template=t, **context) for t, out in FILES.items()}
    manifest = {
        "kernels": {k["name"]: {"inputs": {i["name"]: i["size"] for i in k["inputs"]},
                                "outputs": {o["name"]: o["shape"] for o in k["outputs"]},
                                "ops_after_cse": k["ops"]} for k in kernels},
        "regenerate": COMMAND,
        "versions": {"sympy": sp.__version__, "jinja2": jinja2.__version__},
        "sha256": {name: hashlib.sha256(text.encode()).hexdigest() for name, text in sorted(files.items())},
    }
    files["manifest.json"] = json.dumps(manifest, indent=1) + "\n"
    return files
