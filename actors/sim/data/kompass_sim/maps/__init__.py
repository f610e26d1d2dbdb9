"""Maps of the ``kompass_sim`` share directory (YAML + PGM; see the package's docstring)."""
