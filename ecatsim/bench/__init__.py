"""``ecatsim bench``: the daemon measured against a real master (pysoem), in the wheel.

- :mod:`ecatsim.bench.cli`: the command and its options;
- :mod:`ecatsim.bench.roundtrip`: one segment size's round trips against the daemon and
  against the C echo floor (:mod:`ecatsim.bench.floor`, source ``echo.c``);
- :mod:`ecatsim.bench.bringup`: ``--bringup N``, every frame of a bring-up timed;
- :mod:`ecatsim.bench.master`: the pysoem master, its csp motion and cyclic exchange;
- :mod:`ecatsim.bench.redtest`: ``--master soem``, SOEM's red_test as the bring-up's master,
  built by :mod:`ecatsim.bench.soem` from pysoem's source distribution (also the
  integration tests' C masters);
- :mod:`ecatsim.bench.capture`: packet taps that time every reply;
- :mod:`ecatsim.bench.netns`: network namespaces joined by a veth pair, the daemon in one;
- :mod:`ecatsim.bench.results`: the JSON written to bench/results/.

pysoem is the bench extra (``pip install 'ecatsim[bench]'``), imported only when a bench
runs. Ref: docs/performance.md "How to measure".
"""
