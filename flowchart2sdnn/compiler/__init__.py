"""Compile a chart into a network: loop analysis -> discretize -> emit."""

from .pipeline import Compilation, compile_diagram, compile_file

__all__ = ["Compilation", "compile_diagram", "compile_file"]
