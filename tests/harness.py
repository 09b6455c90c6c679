"""Test harness for real multi-process tests: a router, the services, a probe.

The twin on a bench is :mod:`testbed.twin`, which the benchmarks use too (bench/ imports
nothing of tests/); every name it makes public is handed on here, where the tests have always
found them.
"""

from __future__ import annotations

from testbed.twin import *  # noqa: F403 - this module is testbed.twin's names, under the tests' roof
from testbed.twin import __all__ as __all__
