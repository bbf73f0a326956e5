"""The tests mirror the source tree (issue 13): the tests of ``PKG/.../_NAME.py`` are in
``tests/PKG/.../test_NAME.py`` (``opa/dynamics/_orbits.py``: ``tests/opa/dynamics/test_orbits.py``).
A few modules test a theme that spans source modules (the integrator, the hostile-user
corpus, every ``opa-mc`` subcommand); ``tests/test_layout.py`` lists them and checks the
rule. Every folder is a package, so that tests can import shared helpers as ``tests.X``.

Shared references that owe nothing to the code under test:

- ``tests/truths.py``: closed forms (the linear oscillator, impulse superposition, a mass
  bouncing on and sticking at the wall, the semicircle law's moments and masses);
- ``tests/reference.py``: an independent scipy integrator of the impact oscillator;
- ``tests/reference_splits.py``: a grazing case located with that integrator alone.
"""
