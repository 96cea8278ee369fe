"""The C interface of the compiled drivers, read from the one header ``csrc/vgtarm.h``.

cffi parses the header, so the structures, the status and integrator codes and the exported
functions are written once, in C. :func:`layout_source` generates, from the same parse, a small
C function that reports how the compiler lays the structures out; the tests compare it with
cffi's layout field by field.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

from cffi import FFI

HEADER = Path(__file__).resolve().parent / "csrc" / "vgtarm.h"


@functools.cache
def ffi() -> FFI:
    """The cffi interface built from ``vgtarm.h`` (once per process)."""
    interface = FFI()
    interface.cdef(HEADER.read_text())
    return interface


def enum(name: str) -> dict[str, int]:
    """The constants of one enum of the header, e.g. ``enum("vgt_status")["VGT_DONE"]``."""
    return dict(ffi().typeof(f"enum {name}").relements)


def structures() -> list[str]:
    """Every structure type the header defines (by its typedef name), in a fixed order."""
    typedefs, _, _ = ffi().list_types()
    return sorted(name for name in typedefs if ffi().typeof(name).kind == "struct")


def layout_fields() -> list[tuple[str, str | None]]:
    """``(structure, field)`` pairs in the order ``vgt_layout`` writes them; field None = size."""
    items: list[tuple[str, str | None]] = []
    for name in structures():
        items.append((name, None))
        items.extend((name, field) for field, _ in ffi().typeof(name).fields)
    return items


def layout_source() -> str:
    """C source of ``vgt_layout``, generated from the parsed header."""
    lines = ["#include <stddef.h>", "#include <stdint.h>", '#include "vgtarm.h"', "", "void vgt_layout(long *out)", "{"]
    for i, (struct, field) in enumerate(layout_fields()):
        value = f"sizeof({struct})" if field is None else f"offsetof({struct}, {field})"
        lines.append(f"    out[{i}] = (long){value};")
    lines.append("}")
    return "\n".join(lines) + "\n"


def python_layout() -> list[int]:
    """The same sizes and offsets as cffi computes them."""
    return [ffi().sizeof(s) if f is None else ffi().offsetof(s, f) for s, f in layout_fields()]


def open_library(path: Path) -> Any:
    """The compiled library, with the header's functions bound."""
    return ffi().dlopen(str(path))
