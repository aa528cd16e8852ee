"""The chart: YAML loading, validation and the frozen IR."""

from .model import Block, Diagram, NonlinearWeights, Parameter, Signal, Term
from .validate import diagram_from_text, load_diagram

__all__ = ["Block", "Diagram", "NonlinearWeights", "Parameter", "Signal", "Term", "load_diagram",
           "diagram_from_text"]
