"""funicular's benchmarks against other solvers (not part of the installed package). Run each from
the repository's root as a module: ``.venv/bin/python -m bench.run``, ``-m bench.nets``, ..."""
