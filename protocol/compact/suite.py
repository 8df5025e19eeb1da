"""The compact suite: the path protocol on oblivious transfer (the default).

Messages (step numbers in the frame header), with w-bit digits and D AND levels:

====  =========  =====================================================================
 1    A -> B     HELLO: grid, m, horizon, nonce; the cached setup's id, or kappa (112)
                 base-OT points for a fresh setup (:mod:`protocol.ot.setup`)
 2    B -> A     OFFER: n, nonce; (fresh setup: A and the GGM corrections); the run's OT
                 extension (15 bits per OT); Bob's value bits XOR his choice bits
 3    A -> B     PRODUCTS: every compared value as shares mod 2^(l+1) (:mod:`.products`)
 4    B -> A     DIGITS: the digit bits of Bob's shares XOR his choice bits
 5    A -> B     TABLES: the comparison leaves (:mod:`.millionaire`), the first circuit round
 6..  either     ROUND: openings of the next AND level (:mod:`.gmw`); the last, Bob's,
                 carries his shares of Alice's m result bits
====  =========  =====================================================================

*Values as shares.*  Bob's non-negative inputs are his coordinates shifted by R (X + R,
Y + R in [0, 2 R]) and segment deltas shifted by 2 R; Alice multiplies them by her
coefficients (:func:`protocol.geo.geometry.orient_coefficients`, :func:`~.geometry.projection_key`,
her vertices for O3) and moves the shifts into her constant.  Each value v = a + b mod 2^L,
L = l + 1, with a Alice's share and b Bob's.

*Sign bits.*  For threshold theta, z = v - theta + 2^l lies in (0, 2^(l+1)), so [v >= theta] is
bit l of z.  With A = a - theta + 2^l and B = b (mod 2^(l+1)), bit l of A + B is
A_l xor B_l xor carry, and carry = [B mod 2^l > 2^l - 1 - (A mod 2^l)]: a millionaires'
comparison of Bob's l low bits with Alice's complement.  Its EQ output says
A + B = 2^l - 1 (mod 2^l), i.e. v = theta - 1.  Orientation values use theta = 1: P = [v >= 1]
and Z = EQ = [v = 0].  Projections use theta = 0 (L = not [t >= 0]) and theta = T + 1
(H = [t > T]); the thresholds are Alice's, so Bob cannot tell them apart.
"""

from __future__ import annotations

import dataclasses
import hashlib
import secrets
from collections.abc import MutableMapping

from protocol.compact.gmw import Gmw
from protocol.compact.millionaire import (
    DEFAULT_DIGIT_BITS,
    MAX_DIGIT_BITS,
    LeavesAlice,
    LeavesBob,
)
from protocol.compact.plan import Compared, Offer, Plan, Test, make_plan
from protocol.compact.products import ProductsAlice, ProductsBob
from protocol.errors import (
    InputRangeError,
    LocalProtocolError,
    RemoteProtocolError,
    UnknownSetupError,
)
from protocol.geo.geometry import BobPath, orient_coefficients, projection_key
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import (
    CROSSING,
    NO_SEPARATION,
    Route,
    Separation,
    VolumeSpec,
    pad_route,
    read_separation,
    slab_radius,
    write_separation,
)
from protocol.messages import NONCE_SIZE, Hello, MsgType, Suite, frame, unframe
from protocol.ot.extension import (
    ChooserRots,
    HolderRots,
    check_bytes,
    chooser_extend,
    correction_size,
    holder_extend,
)
from protocol.ot.setup import (
    DEFAULT_BLOCK_BITS,
    DEFAULT_SECURITY,
    ChooserSetup,
    HolderSetup,
    HolderSetupStart,
    chooser_message_size,
    chooser_setup,
)
from protocol.run import AliceSide, BobSide, Kind, Limits, State, check_ask
from protocol.wire.encoding import Reader

__all__ = ["CompactAlice", "CompactBob"]


def _run_nonce(alice: bytes, bob: bytes, setup_id: bytes) -> bytes:
    return hashlib.blake2b(
        alice + bob + setup_id, digest_size=32, person=b"pdc/run/nonce/v1"
    ).digest()


def _circuit_inputs(
    plan: Plan, leaf_shares: list[list[list[tuple[int, int]]]], highs: list[list[int]], flag: int
) -> list[int]:
    """Input shares in the circuit's wire order (see :func:`make_plan`); Bob's flag last."""
    out: list[int] = []
    for per_value, high in zip(leaf_shares, highs, strict=True):
        for per_threshold in per_value:
            for gt, eq in per_threshold:
                out += [gt, eq]
        out += high
    return [*out, flag]


# --------------------------------------------------------------------------- Alice


class CompactAlice(AliceSide):
    """Alice's side of the compact suite."""

    def __init__(
        self,
        route: Route,
        grid: GridSpec,
        *,
        setup: HolderSetup | None,
        limits: Limits,
        horizon_m: int = 0,
        ask_n: int = 0,
        volumes: VolumeSpec = CROSSING,
        digit_bits: int | None = None,
        block_bits: int = DEFAULT_BLOCK_BITS,
        ot_security: int = DEFAULT_SECURITY,
    ) -> None:
        self.ask_n = check_ask(ask_n, limits)
        self.segments = route.segments
        self.m = limits.padded(self.segments)
        self.route = pad_route(route, self.m)
        self.path = self.route.points
        self.grid, self.limits, self.horizon_m = grid, limits, horizon_m
        self.volumes = volumes
        self.digit_bits = digit_bits or DEFAULT_DIGIT_BITS
        if not 1 <= self.digit_bits <= MAX_DIGIT_BITS:
            raise InputRangeError(f"digits of 1..{MAX_DIGIT_BITS} bits")
        self.setup = setup
        self._offer = Offer(self.digit_bits, None, block_bits, ot_security)
        self._fresh = HolderSetupStart(self._offer.blocks) if setup is None else None
        self.nonce = secrets.token_bytes(NONCE_SIZE)
        self.state = State.START
        self.step = 2
        self._hits: list[bool] = []

    def start(self) -> bytes:
        if self.state is not State.START:
            raise LocalProtocolError("already started")
        if self.setup is not None:
            offer = Offer(self.digit_bits, self.setup.setup_id)
        else:
            assert self._fresh is not None
            offer = dataclasses.replace(self._offer, points=self._fresh.message())
        hello = Hello(
            Suite.COMPACT,
            0,
            self.grid,
            self.m,
            self.horizon_m,
            self.nonce,
            offer.to_bytes(),
            self.volumes,
            self.ask_n,
        )
        self.state = State.RUNNING
        return hello.to_bytes()

    def _step(self, data: bytes) -> bytes | None:
        if self.state is not State.RUNNING:
            raise LocalProtocolError(f"cannot receive in state {self.state.value}")
        step = self.step
        reply: bytes | None
        if step == 2:
            reply = self._on_offer(unframe(data, MsgType.OFFER, 2))
        elif step == 4:
            reply = self._on_digits(unframe(data, MsgType.DIGITS, 4))
        else:
            reply = self._on_round(unframe(data, MsgType.ROUND, step))
        self.step += 2
        return reply

    # message 2 -> 3
    def _on_offer(self, body: bytes) -> bytes:
        reader = Reader(body)
        self.n = self.limits.peer_size(reader.uint(2), self.ask_n)
        bob_nonce = reader.take(NONCE_SIZE)
        self.run_volumes = self._agree(read_separation(reader))
        if self._fresh is not None:
            self.setup = self._fresh.finish(reader.take(chooser_message_size(self._fresh.blocks)))
        assert self.setup is not None
        self.plan = plan = make_plan(self.m, self.n, self.grid, self.digit_bits, self.run_volumes)
        nonce = _run_nonce(self.nonce, bob_nonce, self.setup.setup_id)
        extension = reader.take(correction_size(self.setup.blocks, plan.total_rots))
        self.guard_bytes = check_bytes(self.setup.blocks, plan.total_rots)
        flips = reader.take(plan.products.correction_size())
        reader.finish()
        rots = holder_extend(self.setup, nonce, plan.total_rots, extension)
        p, q, r = plan.slices()
        self._leaf_rots = HolderRots(rots.keys0[q], rots.keys1[q])
        self._triple_rots = HolderRots(rots.keys0[r], rots.keys1[r])
        multipliers, constants = self._multipliers()
        products = ProductsAlice(
            plan.products, multipliers, HolderRots(rots.keys0[p], rots.keys1[p])
        )
        message, shares = products.message(flips)
        modulus = 1 << (plan.l + 1)
        self._shares = [(s + c) % modulus for s, c in zip(shares, constants, strict=True)]
        return frame(MsgType.PRODUCTS, 3, message)

    def _agree(self, bob: Separation) -> VolumeSpec:
        """The run's volumes: the larger separation of both, which Alice's box must leave
        room for (Bob's path is cut to the box: anything of his within r of hers must be
        inside it)."""
        separation = self.volumes.separation.widest(bob)
        r = separation.horizontal
        if r > self.limits.max_separation:
            raise RemoteProtocolError(f"peer asks for a separation of {r} grid units")
        if r:
            room = self.grid.range - max(abs(c) for p in self.path for c in p)
            if r >= room:
                raise InputRangeError(
                    f"separation {r} needs {r + 1} grid units around the path, the box leaves "
                    f"{room} (a larger box)"
                )
        return dataclasses.replace(self.volumes, separation=separation)

    def _multipliers(self) -> tuple[list[int], list[int]]:
        """Alice's coefficient per product and constant per form (Bob's shifts folded in)."""
        r = self.grid.range
        a = self.path
        orient_rows = [orient_coefficients(a[i], a[i + 1]) for i in range(self.m)]
        proj_rows = [projection_key(a[i], a[i + 1], self.grid.span) for i in range(self.m)]
        multipliers: list[int] = []
        constants: list[int] = []
        for kind, row, _ in self.plan.layout.values:
            if kind is Kind.O1:
                al, be, ga = orient_rows[row]
                multipliers += [al, be]
                constants.append(ga - (al + be) * r)
            elif kind is Kind.T:
                ex, ey, off, _ = proj_rows[row]
                multipliers += [ex, ey]
                constants.append(off - (ex + ey) * r)
            elif kind is Kind.O3:
                ax, ay = a[row]
                multipliers += [ay, -ax]
                constants.append(-2 * r * (ay - ax))
            elif kind is Kind.T3:  # A_j . d_k (Bob adds -B_k . d_k)
                ax, ay = a[row]
                multipliers += [ax, ay]
                constants.append(-2 * r * (ax + ay))
            else:  # D: |A_j|^2 - 2 A_j . B_k (Bob adds |B_k|^2)
                ax, ay = a[row]
                multipliers += [-2 * ax, -2 * ay]
                constants.append(ax * ax + ay * ay + 2 * r * (ax + ay))
        self._t_max = [t for *_, t in proj_rows]
        return multipliers, constants

    def _share(self, c: Compared) -> tuple[int, list[int]]:
        """Alice's share of one compared value and her thresholds for it."""
        if c.from_form:
            return self._shares[c.index], self._form_thresholds(c)
        volumes = self.run_volumes
        i, _ = self.plan.layout.pairs()[c.index]
        v = volumes.separation.vertical
        if c.test in (Test.BAND_LOW, Test.BAND_HIGH):
            low, high = volumes.clamp_band(self.route.band(i))
            return (v - low if c.test is Test.BAND_LOW else high + v), [0]
        low, high = volumes.clamp_window(self.route.window(i))
        return (-low if c.test is Test.TIME_LOW else high), [0]

    def _form_thresholds(self, c: Compared) -> list[int]:
        _, row, _ = self.plan.layout.values[c.index]
        if c.test is Test.T:
            return [0, self._t_max[row] + 1]
        if c.test is Test.O1:
            if c.thresholds == 1:
                return [1]
            a, b = self.path[row], self.path[row + 1]
            radius = slab_radius(a, b, self.run_volumes.separation.horizontal)
            return [1, -radius, radius + 1]
        if c.test is Test.O3:
            return [1]
        if c.test is Test.D:
            return [self.run_volumes.separation.horizontal**2 + 1]
        return [0]  # O3_LOW, O3_HIGH, T3, T3_HIGH: Bob's shifts hold his own bounds

    def _thresholds(self) -> tuple[list[list[int]], list[list[int]]]:
        """Per value and threshold: the l-bit comparison target and Alice's high bit."""
        targets: list[list[int]] = []
        highs: list[list[int]] = []
        for c in self.plan.compared:
            share, thetas = self._share(c)
            l = c.bits
            top, low = 1 << (l + 1), (1 << l) - 1
            shifted = [(share - theta + (1 << l)) % top for theta in thetas]
            targets.append([low - (s & low) for s in shifted])
            highs.append([s >> l for s in shifted])
        return targets, highs

    # message 4 -> 5
    def _on_digits(self, body: bytes) -> bytes:
        targets, highs = self._thresholds()
        leaves = LeavesAlice(self.plan.leaves, targets, self._leaf_rots)
        tables, shares = leaves.tables(body)
        self.gmw = Gmw(
            self.plan.circuit,
            alice=True,
            rots=self._triple_rots,
            inputs=_circuit_inputs(self.plan, shares, highs, 0),
        )
        return frame(MsgType.TABLES, 5, tables + self.gmw.send())

    # messages 6, 8, ... -> 7, 9, ...
    def _on_round(self, body: bytes) -> bytes | None:
        self.gmw.receive(body)
        if self.gmw.finished:
            self._hits = [bool(b) for b in self.gmw.outputs()[: self.segments]]
            self.state = State.DONE
            return None
        return frame(MsgType.ROUND, self.step + 1, self.gmw.send())


# --------------------------------------------------------------------------- Bob


class CompactBob(BobSide):
    """Bob's side of the compact suite, created from Alice's hello."""

    def __init__(
        self,
        hello: Hello,
        path: BobPath,
        setups: MutableMapping[bytes, ChooserSetup],
        separation: Separation = NO_SEPARATION,
    ) -> None:
        n = path.segments
        self.hello, self.path, self.n, self.m = hello, path, n, hello.m
        self.grid = hello.grid
        offer = Offer.from_bytes(hello.offer)
        volumes = hello.volumes
        self.run_volumes = dataclasses.replace(
            volumes, separation=volumes.separation.widest(separation)
        )
        if self.run_volumes.separation.horizontal >= self.grid.range:
            raise RemoteProtocolError("a separation as wide as the box")
        self.plan = make_plan(self.m, n, self.grid, offer.digit_bits, self.run_volumes)
        setup_reply = b""
        if offer.setup_id is not None:
            found = setups.get(offer.setup_id)
            if found is None:
                raise UnknownSetupError("unknown OT setup (start a fresh one)")
            self.setup = found
        else:
            self.setup, setup_reply = chooser_setup(offer.points, offer.blocks)
            setups[self.setup.setup_id] = self.setup
        nonce_b = secrets.token_bytes(NONCE_SIZE)
        nonce = _run_nonce(hello.nonce, nonce_b, self.setup.setup_id)
        extension, rots = chooser_extend(self.setup, nonce, self.plan.total_rots)
        self.guard_bytes = check_bytes(self.setup.blocks, self.plan.total_rots)
        p, q, r = self.plan.slices()
        self._leaf_rots = ChooserRots(rots.choices[q], rots.keys[q])
        self._triple_rots = ChooserRots(rots.choices[r], rots.keys[r])
        self.products = ProductsBob(
            self.plan.products, self._values(), ChooserRots(rots.choices[p], rots.keys[p])
        )
        self._reply = frame(
            MsgType.OFFER,
            2,
            n.to_bytes(2, "big")
            + nonce_b
            + write_separation(separation)
            + setup_reply
            + extension
            + self.products.corrections(),
        )
        self.state = State.RUNNING
        self.step = 3

    def first_reply(self) -> bytes:
        return self._reply

    def _values(self) -> list[int]:
        r = self.grid.range
        values = [c + r for point in self.path.points for c in point]
        for k in range(self.n):
            dx, dy, _ = self.path.line(k)
            values += [dx + 2 * r, dy + 2 * r]
        return values

    def _step(self, data: bytes) -> bytes | None:
        if self.state is not State.RUNNING:
            raise LocalProtocolError(f"cannot receive in state {self.state.value}")
        step = self.step
        if step == 3:
            reply = self._on_products(unframe(data, MsgType.PRODUCTS, 3))
        elif step == 5:
            reply = self._on_tables(unframe(data, MsgType.TABLES, 5))
        else:
            reply = self._on_round(unframe(data, MsgType.ROUND, step))
        self.step += 2
        return reply

    def _form_constants(self) -> list[int]:
        """Bob's own term of each form: K_k (O3), -B_k . d_k (T3), |B_k|^2 (D)."""
        points = self.path.points
        out = []
        for kind, _, k in self.plan.layout.values:
            if kind is Kind.O3:
                out.append(self.path.line(k)[2])
            elif kind is Kind.T3:
                dx, dy, _ = self.path.line(k)
                out.append(-(points[k][0] * dx + points[k][1] * dy))
            elif kind is Kind.D:
                out.append(points[k][0] ** 2 + points[k][1] ** 2)
            else:
                out.append(0)
        return out

    def _segment_bounds(self, k: int) -> tuple[int, int]:
        """(R'_k, L_k) of Bob's segment k; a link's (-1, 0) keeps its slab empty."""
        if k in self.path.links:
            return -1, 0
        a, b = self.path.points[k], self.path.points[k + 1]
        r = self.run_volumes.separation.horizontal
        return slab_radius(a, b, r), (b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2

    def _value(self, c: Compared, forms: list[int]) -> int:
        """Bob's share of one compared value: a form's with his shift, or his pair input."""
        layout = self.plan.layout
        if c.from_form:
            k = layout.values[c.index][2]
            if c.test is Test.O3_LOW:
                return forms[c.index] + self._segment_bounds(k)[0]
            if c.test is Test.O3_HIGH:
                return forms[c.index] - self._segment_bounds(k)[0] - 1
            if c.test is Test.T3_HIGH:
                return forms[c.index] - self._segment_bounds(k)[1] - 1
            return forms[c.index]
        volumes = self.run_volumes
        _, k = layout.pairs()[c.index]
        if c.test in (Test.BAND_LOW, Test.BAND_HIGH):
            band = volumes.clamp_band(None if self.path.bands is None else self.path.bands[k])
            return band[1] if c.test is Test.BAND_LOW else -band[0]
        window = volumes.clamp_window(None if self.path.windows is None else self.path.windows[k])
        return window[1] if c.test is Test.TIME_LOW else -window[0]

    # message 3 -> 4
    def _on_products(self, body: bytes) -> bytes:
        shares = self.products.shares(body)
        forms = [s + c for s, c in zip(shares, self._form_constants(), strict=True)]
        values = []
        self._highs = []
        for c in self.plan.compared:
            value = self._value(c, forms) % (1 << (c.bits + 1))
            self._highs.append(value >> c.bits)
            values.append(value & ((1 << c.bits) - 1))
        self.leaves = LeavesBob(self.plan.leaves, values, self._leaf_rots)
        return frame(MsgType.DIGITS, 4, self.leaves.corrections())

    # message 5 -> 6
    def _on_tables(self, body: bytes) -> bytes:
        size = self.plan.leaves.table_size()
        shares = self.leaves.shares(body[:size])
        counts = self.plan.leaves.thresholds
        highs = [[h] * count for h, count in zip(self._highs, counts, strict=True)]
        self.gmw = Gmw(
            self.plan.circuit,
            alice=False,
            rots=self._triple_rots,
            inputs=_circuit_inputs(self.plan, shares, highs, int(self.path.everywhere)),
        )
        self.gmw.receive(body[size:])
        return self._send()

    def _on_round(self, body: bytes) -> bytes:
        self.gmw.receive(body)
        return self._send()

    def _send(self) -> bytes:
        message = frame(MsgType.ROUND, self.step + 1, self.gmw.send())
        if self.gmw.finished:
            self.state = State.DONE
        return message
