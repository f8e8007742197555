"""Helpers the tests share, importable from any test module as ``helpers.<module>``.

``tests/`` is on ``sys.path`` (``[tool.pytest.ini_options] pythonpath``), so any subset of the
test folders collects, in any order:

- :mod:`helpers.data`: where the real volumes are (``INTUITF_DATA``), ``data_file`` (skips
  when one is missing).
- :mod:`helpers.tfs`: hand-made transfer functions (``tooth_tf``, ``random_tf``).
- :mod:`helpers.ranking`: a cheap synthetic judge ranking TFs by closeness to a hidden target.
- :mod:`helpers.waiting`: wait for a condition (a file, a status, a count), never a bare sleep.
- :mod:`helpers.vtkref`: the VTK scene the renderer is checked against.
- :mod:`helpers.web_backend`: a small web app, a live uvicorn, waiting for a run.
- :mod:`helpers.browser`: start and stop ``intuitf serve`` for the browser tests, Chromium.
"""
