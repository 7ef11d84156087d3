"""The bag of the merger's outputs (io/output_bag.py): what is kept when a record is thinned,
and the QoS each topic is offered with."""

from __future__ import annotations

from rosbags.rosbag2.metadata import QosDurability, QosHistory, QosReliability

from multi_robot_mapper.io.output_bag import offered_qos, thinned


def test_thinning_keeps_at_most_the_most_evenly_spread_with_first_and_last() -> None:
    assert thinned(4, 10).tolist() == [0, 1, 2, 3]  # fewer than the most: every one
    assert thinned(10, 10).tolist() == list(range(10))
    assert thinned(101, 5).tolist() == [0, 25, 50, 75, 100]
    kept = thinned(1000, 7)
    assert len(kept) == 7 and kept[0] == 0 and kept[-1] == 999
    assert thinned(3, 2).tolist() == [0, 2]  # the last always kept


def test_latched_topics_are_transient_local_with_depth_one_the_others_volatile() -> None:
    latched, live = offered_qos(True), offered_qos(False, depth=20)
    assert latched.durability == QosDurability.TRANSIENT_LOCAL and latched.depth == 1
    assert live.durability == QosDurability.VOLATILE and live.depth == 20
    for qos in (latched, live):
        assert qos.reliability == QosReliability.RELIABLE
        assert qos.history == QosHistory.KEEP_LAST
