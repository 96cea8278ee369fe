"""The ``vgtarm`` command line: the parser and the core commands (:mod:`.command`), one module per
family of commands (:mod:`.mujoco`, :mod:`.stack`, :mod:`.study`, :mod:`.visual`) and the shared
option types (:mod:`.options`)."""

from .command import build_parser, main

__all__ = ["build_parser", "main"]
