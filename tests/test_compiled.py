"""The compiled backend: disk cache reuse and the interpreter fallback without a compiler."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import vgtarm
from vgtarm.model import compiled, compiling, library_cache


def test_cache_is_reused_and_keyed_by_the_sources(robot):
    backend = compiled.get_backend()
    if not isinstance(backend, compiled.CompiledBackend):
        pytest.skip("no C compiler on this machine")
    compiler = compiled.find_compiler()
    assert compiler is not None
    again = compiled._compiled_backend(compiler)  # a second load: from the cache, no rebuild
    assert again.library_path == backend.library_path
    assert library_cache._cache_key(compiler) in backend.library_path.name


def test_without_a_compiler_the_interpreter_runs_the_same_model(monkeypatch, caplog, robot):
    monkeypatch.setattr(compiling, "find_compiler", lambda: None)
    with caplog.at_level(logging.WARNING, logger="vgtarm"):
        backend = compiled.get_backend.__wrapped__("auto")
    assert isinstance(backend, compiled.InterpretedBackend)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "no C compiler" in warnings[0].getMessage()
    assert "\n" not in warnings[0].getMessage()
    slow = vgtarm.Robot(robot.parameters, backend)
    q = robot.parameters.home + np.linspace(-0.01, 0.01, 7)
    np.testing.assert_allclose(slow.mass_matrix(q), robot.mass_matrix(q), rtol=1e-13, atol=1e-15)


def test_unknown_backend_choice_is_named():
    with pytest.raises(ValueError, match="VGTARM_BACKEND = 'gpu'"):
        compiled.get_backend.__wrapped__("gpu")
