"""The chart: YAML loading, validation, the frozen IR and the writer back to YAML.

Layer 2: imports only the expression language and errors below it (tests/test_layers.py checks every layer).
"""

from .model import Block, Diagram, NonlinearWeights, Parameter, Signal, Term
from .validate import diagram_from_text, load_diagram

__all__ = ["Block", "Diagram", "NonlinearWeights", "Parameter", "Signal", "Term", "load_diagram",
           "diagram_from_text"]
