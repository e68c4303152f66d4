"""Which imports wait until a function needs them, and why: the one place that says so.

``import ials_zoo`` and ``ials-zoo --help`` take about 0.3 s (0.28 and 0.31 s: ``farm-bench -n 15
-- python -c "import ials_zoo"``, median, at commit 72c6df4 on 2 cores). The modules below would
each add far more than that to every command, every worker process and every test that does not
use them, so only they are imported inside functions; the rest of the package imports at the top
of its files. Measured as ``python -c "import M"``, median wall seconds of 5 on the same machine
(which includes Python's own 0.02 s start), with torch 2.13.0, SB3 2.9, scipy 1.17, matplotlib
3.11, Ray 2.60 and SUMO 1.28:

==========================  =======  ==============================================
module                      seconds  what needs it
==========================  =======  ==============================================
``torch``                   1.43     AIPs, learners, policies
``stable_baselines3``       1.55     single-agent PPO (brings torch)
``scipy``                   0.82     confidence intervals (``scipy.stats``)
``matplotlib``              0.50     plots (``matplotlib.pyplot``)
``ray``                     0.43     the ``ray`` backend and extra
``libsumo``/``sumo``        0.29     a SUMO simulation (and it is one per process)
==========================  =======  ==============================================

The others in :data:`HEAVY` are of the same kind (they import one of these, or are an extra
that may be missing). A module of ours that imports one of them at its top is heavy too, and is
imported inside functions by the light modules that use it.

Two more reasons keep an import inside a function, each said on its line or here:

* a domain's descriptor (``<domain>/domain.py``) names its env, local simulator and renderer
  without loading them, so ``get_domain`` and ``ials-zoo --help`` stay light;
* ``# lazy: <why>`` on the import's line (an optional dependency, a platform's module).

``tests/test_imports.py`` holds the package to this page.
"""

HEAVY = frozenset({
    "torch", "stable_baselines3", "sb3_contrib", "torchrl", "tensordict", "safetensors", "scipy", "matplotlib",
    "PIL", "imageio", "ray", "libsumo", "traci", "sumolib", "sumo", "supersuit", "jsonschema", "playwright",
})
"""Top-level packages that are imported only where a function needs them (module docstring)."""

LAZY_FILES = ("domain.py",)
"""File names whose imports all wait: a domain's descriptor (module docstring)."""

__all__ = ["HEAVY", "LAZY_FILES"]
