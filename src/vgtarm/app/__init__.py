"""The command line, the pictures and the reports: parsing, printing and files over the library.

Everything here is also a name of :mod:`vgtarm` (``vgtarm.run_case``, ``vgtarm.reproduce``,
``vgtarm.comparison_figure``, ...); import those rather than these modules."""
