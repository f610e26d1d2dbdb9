"""Data that ships with the package: the router benchmark's routes and labeled queries."""
from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent
