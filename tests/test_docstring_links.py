"""Every cross-reference to a ``vgtarm.`` name in the package's docstrings (``:func:`vgtarm.x.y```,
``:class:`~vgtarm.z```, ...) names something that exists: a module, then attributes of it."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import vgtarm

PACKAGE = Path(vgtarm.__file__).resolve().parent
ROLE = re.compile(r":(?:func|class|meth|mod|attr|data|exc|obj):`~?(vgtarm(?:\.[A-Za-z_][A-Za-z_0-9]*)+)`")
#: Names documented as instance attributes (set in ``__init__``), not reachable on the class.
INSTANCE_ATTRIBUTES = {"vgtarm.Robot.parameters"}


def _resolves(name: str) -> bool:
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            value = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attribute in parts[i:]:
            fields = getattr(value, "__dataclass_fields__", {})
            if attribute in fields and not hasattr(value, attribute):
                return True  # a dataclass field without a default: documented on the class
            if not hasattr(value, attribute):
                return False
            value = getattr(value, attribute)
        return True
    return False


def test_every_vgtarm_reference_in_a_docstring_resolves():
    broken = sorted(
        f"{path.relative_to(PACKAGE)}: {name}"
        for path in PACKAGE.rglob("*.py")
        for name in ROLE.findall(path.read_text())
        if name not in INSTANCE_ATTRIBUTES and not _resolves(name)
    )
    assert broken == []
