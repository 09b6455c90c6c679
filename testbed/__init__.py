"""The twin on a bench: what the tests (``tests/``) and the benchmarks (``bench/``) both run
Lunaris with, so that a benchmark needs nothing of the tests.

- :mod:`testbed.twin`: a router, the services as processes, a probe (``tests/harness.py``
  hands its names on to the tests);
- :mod:`testbed.deployment`, :mod:`testbed.netns`, :mod:`testbed.machines`,
  :mod:`testbed.remote`: a deployment as generated (identities, TLS, access control), on
  loopback or on machines made of network namespaces, and a client on any of them;
- :mod:`testbed.browser`: Debian's headless Chromium; :mod:`testbed.fuzz`: bad payloads for
  every writable key; :mod:`testbed.progpy_cell`: the reference cell run by NASA ProgPy and by
  Lunaris; :mod:`testbed.procfs`: what a process costs (CPU, memory).

Lunaris's processes are started and stopped by :mod:`lunaris.processes`, as ``lunaris up``
starts and stops them. Nothing of Lunaris imports this package (tests/architecture).
"""
