"""`emos bench NAME`: one module per benchmark (tools/cli/__init__.py lists them). The `*_system.py`
files are recipes the benchmarks run under `emos run`: they start a system when executed, so
nothing imports them."""
