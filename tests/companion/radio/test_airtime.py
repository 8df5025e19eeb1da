"""Time on air (Semtech check values), profiles, and the duty-cycle budget."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.radio.airtime import PROFILES, DutyCycle, lora_airtime, profile
from companion.radio.frames import OVERHEAD
from companion.sim.bench_link import header_share


@pytest.mark.parametrize(
    ("sf", "size", "ms"),
    [(7, 10, 41.216), (9, 13, 164.864), (11, 10, 577.536)],
)
def test_semtech_check_values(sf: int, size: int, ms: float) -> None:
    assert lora_airtime(size, sf) * 1000 == pytest.approx(ms, abs=1e-6)


def test_full_frame_airtimes_match_the_field_notes() -> None:
    assert lora_airtime(222, 7) == pytest.approx(0.348, abs=0.001)
    assert lora_airtime(222, 9) == pytest.approx(1.1, abs=0.05)
    assert lora_airtime(222, 12) == pytest.approx(8.0, abs=0.1)


def test_profile_names_are_stable() -> None:
    assert set(PROFILES) == {
        "eu868-sf7",
        "eu868-sf9",
        "eu868-sf12",
        "eu868-g3-sf7",
        "us915-sf7",
        "us915-sf9",
        "ideal",
    }
    with pytest.raises(ValueError, match="unknown link profile"):
        profile("eu868-sf8")


def test_us915_dwell_caps_the_frame() -> None:
    for name in ("us915-sf7", "us915-sf9"):
        p = PROFILES[name]
        assert p.airtime(p.max_frame) <= 0.400
        assert p.max_frame == p.mtu or p.airtime(p.max_frame + 1) > 0.400
    assert PROFILES["us915-sf9"].max_frame == 66  # LoRaWAN DR1: 53 B + 13 B of MAC overhead
    assert PROFILES["us915-sf7"].max_frame == 222


@pytest.mark.parametrize("name", ["eu868-sf7", "eu868-sf9", "eu868-sf12", "us915-sf7", "ideal"])
def test_header_overhead_at_default_mtu_is_at_most_8_percent(name: str) -> None:
    p = PROFILES[name]
    assert p.max_frame >= 222
    assert header_share(p) <= 0.08
    assert OVERHEAD / p.max_frame <= 0.08


def test_duty_cycle_blocks_then_frees_after_the_window() -> None:
    duty = DutyCycle(36.0, 3600.0, reserve=0.1)
    t = 0.0
    for _ in range(90):  # 90 x 0.36 s = 32.4 s: the data share of the budget
        assert duty.earliest(t, 0.36) == t
        duty.record(t, 0.36)
        t += 0.4
    blocked = duty.earliest(t, 0.36)
    assert blocked == pytest.approx(3600.0)  # the first frame leaves the window
    assert duty.earliest(t, 0.05, control=True) == t  # the reserve still serves an ACK


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 50.0), st.floats(0.01, 3.0), st.booleans()), max_size=300))
def test_duty_cycle_never_exceeds_the_budget_in_any_window(
    plan: list[tuple[float, float, bool]],
) -> None:
    duty = DutyCycle(36.0, 3600.0)
    sent: list[tuple[float, float]] = []
    now = 0.0
    for gap, airtime, control in plan:
        now = duty.earliest(now + gap, airtime, control=control)
        duty.record(now, airtime)
        sent.append((now, airtime))
        now += airtime
    for start, _ in sent:  # every window that starts at a transmission
        in_window = sum(a for s, a in sent if start <= s < start + 3600.0 - 1e-6)
        assert in_window <= 36.0 + 1e-6
