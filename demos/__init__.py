"""The demos, one script per case study (``soro demo NAME`` runs ``NAME.py``'s ``main``). Installed as the package
data ``soro.demos`` (pyproject.toml), so that an installed copy lists and runs them (:mod:`soro.demo`)."""
