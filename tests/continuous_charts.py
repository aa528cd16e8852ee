"""Charts built directly from the IR dataclasses, for the continuous-oracle and excitation tests."""

from __future__ import annotations

from flowchart2sdnn.diagram.model import Block, Diagram, NonlinearWeights, Parameter, Signal, Term
from flowchart2sdnn.expr import parse_expr

# Friction curves of the two-mass test chart: Coulomb-like steep tanh plus a viscous-like flat one.
FRICTION1 = NonlinearWeights(a=(50.0, 0.1), v=(0.6, 2.0))
FRICTION2 = NonlinearWeights(a=(40.0, 0.1), v=(0.8, 3.0), b=(0.0, 0.0))
TMS_PARAMETERS = {"J1": 0.1912, "J2": 0.3838, "c": 477.0, "d": 0.24}


def block(name: str, kind: str, *terms: str, **fields) -> Block:
    """A block; terms are signal names, '-name' for sign -1; a string `k` is parsed as an expression."""
    if isinstance(fields.get("k"), (str, int, float)):
        fields["k"] = parse_expr(str(fields["k"]))
    inputs = tuple(Term(t[1:], -1) if t.startswith("-") else Term(t) for t in terms)
    return Block(name, kind, inputs, **fields)


def chart(inputs, outputs, blocks, parameters=None, sample_time=1e-3, name="test") -> Diagram:
    return Diagram(
        name=name,
        sample_time=sample_time,
        inputs=tuple(Signal(s) for s in inputs),
        outputs=tuple(Signal(s) for s in outputs),
        parameters=tuple(Parameter(p, v) for p, v in (parameters or {}).items()),
        blocks=tuple(blocks),
    )


def two_mass(sample_time: float = 1e-3, friction: bool = True) -> Diagram:
    """The two-mass system of the paper (Fig. 3): motor torque M1 in, speeds w2 and w1 out."""
    blocks = [
        block("MB1", "sum", "M1", "-MC", "-MD", "-MR1"),
        block("a1", "gain", "MB1", k="1/J1"),
        block("w1", "integrator", "a1", init=0.0),
        block("dw", "sum", "w1", "-w2"),
        block("dphi", "integrator", "dw", init=0.0),
        block("MC", "gain", "dphi", k="c"),
        block("MD", "gain", "dw", k="d"),
        block("MB2", "sum", "MC", "MD", "-MR2"),
        block("a2", "gain", "MB2", k="1/J2"),
        block("w2", "integrator", "a2", init=0.0),
        block("MR1", "nonlinear", "w1", weights=FRICTION1 if friction else NonlinearWeights((0.0,), (0.0,))),
        block("MR2", "nonlinear", "w2", weights=FRICTION2 if friction else NonlinearWeights((0.0,), (0.0,))),
    ]
    return chart(["M1"], ["w2", "w1"], blocks, TMS_PARAMETERS, sample_time, name="tms")


def integrator_plant(sample_time: float = 1e-3) -> Diagram:
    """speed = integral of u: the simplest globally integrating plant."""
    return chart(["u"], ["speed"], [block("speed", "integrator", "u", init=0.0)], sample_time=sample_time)
