"""Random circuits for the engines' tests."""

from __future__ import annotations

from hypothesis import strategies as st

from protocol.circuits.boolean import Circuit


@st.composite
def circuits(draw: st.DrawFn, max_inputs: int = 6, max_gates: int = 40) -> Circuit:
    c = Circuit()
    wires = [c.input() for _ in range(draw(st.integers(1, max_inputs)))]
    for _ in range(draw(st.integers(0, max_gates))):
        op = draw(st.sampled_from(["xor", "not", "and", "and", "or"]))
        a, b = draw(st.sampled_from(wires)), draw(st.sampled_from(wires))
        if op == "xor":
            wires.append(c.xor(a, b))
        elif op == "not":
            wires.append(c.not_(a))
        elif a != b:
            wires.append(c.and_(a, b) if op == "and" else c.or_(a, b))
    for wire in draw(st.lists(st.sampled_from(wires), min_size=1, max_size=6)):
        c.output(wire)
    return c
