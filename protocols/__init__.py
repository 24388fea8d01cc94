"""vasim's shipped data files, installed as the package ``vasim.protocols``.

This folder holds TOML data only: ``schemas/`` (fixture schemas), ``studies/`` (study
protocols), ``scenes/`` (abdomen scenes) and ``robots/`` (MRCP robot files). The build maps it
to ``vasim.protocols`` (``[tool.setuptools.package-dir]`` in ``pyproject.toml``) so an
installed wheel finds it through :mod:`importlib.resources`; see ``vasim.core.resources``.
"""
