"""``python -m vgtarm``: the ``vgtarm`` command (see :mod:`vgtarm._entry`)."""

import sys

from vgtarm._entry import main

if __name__ == "__main__":
    sys.exit(main())
