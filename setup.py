"""The package's three optional C extensions (metadata and everything else are in setup.cfg).

Each is small, plain C against Python's headers: the impact world's substep loop
(impact_env/transport/native.py says why), the tether world's kinematic substep loop
(impact_env/tether/native.py) and the online STL monitor of the shipped formula classes
(impact_env/stl/compiled.py). ``optional=True``: a machine without a C compiler still installs the package,
which then runs the pure-Python paths (same results, slower) and says so in one line.
"""

import sys

from setuptools import Extension, setup

# the Python paths' arithmetic, bit for bit: no fused multiply-add, and libm's sin/cos called as Python calls
# them (gcc would otherwise merge sin and cos of one angle into sincos)
FLAGS = [] if sys.platform == "win32" else ["-O2", "-ffp-contract=off", "-fno-builtin-sin", "-fno-builtin-cos",
                                           "-fno-builtin-sincos"]

setup(ext_modules=[
    Extension("impact_env.transport._substeps", ["impact_env/transport/_substeps.c"], extra_compile_args=FLAGS,
              optional=True),
    Extension("impact_env.tether._substeps", ["impact_env/tether/_substeps.c"], extra_compile_args=FLAGS,
              optional=True),
    Extension("impact_env.stl._cmonitor", ["impact_env/stl/_cmonitor.c"], extra_compile_args=FLAGS, optional=True),
])
