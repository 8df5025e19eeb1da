"""The link's counters: the channel's use over the last seconds."""

from __future__ import annotations

import pytest

from companion.radio.stats import ChannelUse


def test_the_share_counts_only_the_part_of_a_frame_inside_the_window() -> None:
    use = ChannelUse(horizon_s=30.0)
    assert use.share(10.0, 5.0) == 0.0
    use.add(6.0, 1.0)  # on the air 5..6
    use.add(9.0, 2.0)  # 7..9
    assert use.share(9.0, 5.0) == pytest.approx(3.0 / 5.0)
    assert use.share(9.0, 2.5) == pytest.approx(2.0 / 2.5)  # only 6.5..9: the second frame
    assert use.share(9.0, 3.5) == pytest.approx(2.5 / 3.5)  # half of the first one
    assert use.share(20.0, 5.0) == 0.0


def test_the_share_is_bounded_by_one_and_forgets_beyond_its_horizon() -> None:
    use = ChannelUse(horizon_s=10.0)
    for end in range(1, 40):  # overlapping frames (heard and sent): never above one
        use.add(float(end), 2.0)
    assert use.share(39.0, 5.0) == 1.0
    assert use.share(39.0, 100.0) == 1.0  # a window beyond the horizon is the horizon
    assert len(use._frames) <= 11
    assert use.share(39.0, 0.0) == 0.0
