"""The tools tier (``emos.tools``): what drives or measures whole systems from above the product.

The ``emos`` command line (:mod:`emos.tools.cli`), every benchmark (:mod:`emos.tools.bench`), the
BARN harness (:mod:`emos.tools.barn`) and the plotting they share. Dependencies point one way
(DESIGN.md): ``emos`` <- ``emos.actors`` <- ``emos.supervisor`` <- ``emos.tools`` (with
``emos.chaos``); nothing below this package imports it, lazily or not (tests/test_layers.py).
"""
