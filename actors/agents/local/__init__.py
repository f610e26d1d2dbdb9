"""Local models that run offline on the robot's CPU.

Every model here loads weights that ship inside an installed Python package or an OS package:
nothing is downloaded at run time. Heavy libraries (torch, sentence-transformers, cv2) are
imported lazily inside the modules that need them, so importing this package is cheap.
"""
