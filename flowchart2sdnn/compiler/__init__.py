"""Compile a chart into a network: loop analysis -> discretize -> emit."""

from .pipeline import Compilation, check_file, compile_diagram, compile_file

__all__ = ["Compilation", "check_file", "compile_diagram", "compile_file"]
