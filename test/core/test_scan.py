"""Beams to points: geometry with known answers, and every kind of bad scan."""

from __future__ import annotations

import math

import numpy as np
import pytest

from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.scan import LaserScanData, ScanError, scan_points

ONE_DEGREE = math.radians(1.0)


def make_scan(
    ranges,
    angle_min=-math.pi / 2,
    increment=ONE_DEGREE,
    angle_max=None,
    range_min=0.05,
    range_max=30.0,
    intensities=None,
) -> LaserScanData:
    ranges = np.asarray(ranges, dtype=float)
    if angle_max is None:
        angle_max = angle_min + increment * (len(ranges) - 1)
    return LaserScanData(ranges, angle_min, angle_max, increment, range_min, range_max, intensities)


def kinds(result) -> set[str]:
    return {n.kind for n in result.notices}


def test_beam_angles_follow_angle_min_plus_i_increment() -> None:
    result = scan_points(make_scan([1.0, 2.0, 3.0], angle_min=0.0, increment=math.pi / 2))
    np.testing.assert_allclose(result.points, [[1, 0], [0, 2], [-3, 0]], atol=1e-12)
    assert result.notices == ()


def test_readings_outside_range_limits_are_dropped() -> None:
    result = scan_points(make_scan([0.01, 0.05, 1.0, 30.0, 31.0], range_min=0.05, range_max=30.0))
    np.testing.assert_array_equal(result.beam_index, [1, 2])
    assert result.invalid_count == 3


def test_nan_and_inf_are_no_return_with_a_notice() -> None:
    result = scan_points(make_scan([1.0, np.nan, np.inf, -np.inf, 2.0]))
    np.testing.assert_array_equal(result.beam_index, [0, 4])
    assert "non_finite_ranges" in kinds(result)
    assert "1 NaN and 2 inf" in result.notices[0].message


def test_all_invalid_gives_no_points_and_a_notice() -> None:
    result = scan_points(make_scan([np.nan] * 10))
    assert result.points.shape == (0, 2)
    assert "no_valid_ranges" in kinds(result)


def test_zero_beams_is_refused() -> None:
    with pytest.raises(ScanError, match="no beams") as err:
        scan_points(make_scan([]))
    assert err.value.kind == "no_beams"


def test_ten_thousand_consistent_beams_are_processed() -> None:
    n = 10_000
    inc = 2 * math.pi / n
    result = scan_points(make_scan(np.full(n, 5.0), angle_min=-math.pi, increment=inc))
    assert len(result.points) == n and result.notices == ()
    np.testing.assert_allclose(np.hypot(*result.points.T), 5.0)


def test_ten_thousand_beams_on_a_180_beam_geometry_are_refused() -> None:
    scan = make_scan(np.full(10_000, 5.0), angle_max=math.pi / 2)
    with pytest.raises(ScanError, match="10000 beams") as err:
        scan_points(scan)
    assert err.value.kind == "beam_span"


def test_more_than_max_beams_is_refused() -> None:
    with pytest.raises(ScanError, match="max_beams"):
        scan_points(make_scan(np.ones(50), increment=0.001), max_beams=20)


def test_angle_fields_that_contradict_the_beam_count_are_refused() -> None:
    scan = make_scan(np.ones(200), angle_max=math.pi / 2)  # fields describe 181 beams
    with pytest.raises(ScanError, match="describe 181") as err:
        scan_points(scan)
    assert (err.value.kind, err.value.field) == ("beam_count", "ranges")
    # One beam of slack either way: drivers disagree on where angle_max lies.
    assert len(scan_points(make_scan(np.ones(182), angle_max=math.pi / 2)).points) == 182


def test_known_answer_points_and_beams_dropped_by_kind() -> None:
    # ranges [1, inf, 2, NaN, 3], increment pi/4 from 0, range_min 2, range_max 10: beam 0 is
    # too close, 1 no return, 3 erroneous; beams 2 (90 deg) and 4 (180 deg) are the points.
    scan = LaserScanData(
        np.array([1.0, np.inf, 2.0, np.nan, 3.0]), 0.0, math.pi, math.pi / 4, 2.0, 10.0
    )
    result = scan_points(scan)
    np.testing.assert_allclose(result.points, [[0.0, 2.0], [-3.0, 0.0]], atol=1e-15)
    np.testing.assert_array_equal(result.beam_index, [2, 4])
    assert dict(result.dropped) == {"below_range_min": 1, "+inf": 1, "nan": 1}


def test_mixed_infinities_and_out_of_range_beams_are_counted_by_kind() -> None:
    ranges = [np.inf, -np.inf, np.inf, 0.01, 31.0, 30.0, 5.0, np.nan, -1.0]
    result = scan_points(make_scan(ranges, range_min=0.05, range_max=30.0))
    assert dict(result.dropped) == {
        "+inf": 2,
        "-inf": 1,
        "nan": 1,
        "below_range_min": 2,
        "beyond_range_max": 2,
    }
    assert len(result.points) == 1
    assert dict(scan_points(make_scan([np.nan] * 7)).dropped) == {"nan": 7}


def test_negative_range_min_is_refused() -> None:
    with pytest.raises(ScanError, match="range_min is negative") as err:
        scan_points(make_scan(np.ones(5), range_min=-0.1))
    assert (err.value.kind, err.value.field) == ("range_limits", "range_min")


@pytest.mark.parametrize("increment", [0.0, float("nan"), float("inf"), float("-inf")])
def test_zero_or_non_finite_increment_is_refused(increment: float) -> None:
    scan = LaserScanData(np.ones(5), 0.0, 0.04, increment, 0.0, 10.0)
    with pytest.raises(ScanError) as err:
        scan_points(scan)
    assert err.value.field == "angle_increment"


@pytest.mark.parametrize("limits", [(float("nan"), 10.0), (0.0, float("inf")), (0.0, float("nan"))])
def test_non_finite_range_limits_are_refused(limits: tuple[float, float]) -> None:
    with pytest.raises(ScanError, match="not a finite number"):
        scan_points(make_scan(np.ones(5), range_min=limits[0], range_max=limits[1]))


@pytest.mark.parametrize("increment", [1e-30, 1e-8, 1e-4])
def test_degenerate_scans_no_laser_makes_are_refused_before_the_front_end(
    increment: float,
) -> None:
    # 1081 beams within 6 degrees or much less: every point on a line or on one spot.
    ranges = 3.0 + 0.01 * np.arange(1081)
    scan = make_scan(ranges, angle_min=-0.05, increment=increment)
    if increment == 1e-30:  # angle_max == angle_min in floating point: the fields contradict
        with pytest.raises(ScanError, match="describe 1:"):
            extract_scan(scan, ExtractionConfig())
        return
    assert len(scan_points(scan).points) == 1081  # the fields themselves are consistent
    with pytest.raises(ScanError, match="min_field_of_view") as err:
        extract_scan(scan, ExtractionConfig())
    assert (err.value.kind, err.value.field) == ("field_of_view", "angle_increment")
    # The rule is a parameter: 0 lets such scans through (for a user who really has one).
    extract_scan(scan, ExtractionConfig(min_field_of_view=0.0))


def test_one_beam_is_handled_and_a_scan_without_a_reading_refused() -> None:
    one = LaserScanData(np.array([2.0]), 0.3, 0.3, 0.0, 0.0, 10.0)
    np.testing.assert_allclose(scan_points(one).points, [[2 * math.cos(0.3), 2 * math.sin(0.3)]])
    with pytest.raises(ScanError) as err:  # one beam spans no field of view
        extract_scan(one, ExtractionConfig())
    assert err.value.kind == "field_of_view"
    with pytest.raises(ScanError) as err:
        extract_scan(make_scan([np.nan] * 181), ExtractionConfig())
    assert (err.value.kind, err.value.field) == ("no_valid_ranges", "ranges")


def test_upside_down_laser_gives_the_mirrored_scans_endpoints() -> None:
    # angle_min > angle_max with a negative increment: the same beams listed clockwise.
    rng = np.random.default_rng(1)
    ranges = rng.uniform(1.0, 8.0, 271)
    forward = make_scan(ranges, angle_min=-2.0, increment=0.015)
    mirrored = LaserScanData(
        ranges[::-1].copy(), forward.angle_max, forward.angle_min, -0.015, 0.05, 30.0
    )
    a, b = (
        extract_scan(forward, ExtractionConfig())[0],
        extract_scan(mirrored, ExtractionConfig())[0],
    )
    np.testing.assert_allclose(b.segments, a.segments, atol=1e-6)


def test_negative_increment_gives_the_same_points_counter_clockwise() -> None:
    ranges = np.linspace(1.0, 2.0, 91)
    forward = scan_points(make_scan(ranges, angle_min=0.0, increment=math.radians(1)))
    backward = scan_points(
        make_scan(ranges[::-1], angle_min=math.radians(90), increment=-math.radians(1))
    )
    np.testing.assert_allclose(backward.points, forward.points, atol=1e-12)
    assert "negative_increment" in kinds(backward)


def test_intensities_of_another_length_are_ignored_with_a_notice() -> None:
    result = scan_points(make_scan(np.ones(10), intensities=np.ones(3)))
    assert len(result.points) == 10
    assert "intensities_length" in kinds(result)


def test_angle_max_below_angle_min_with_positive_increment_is_refused() -> None:
    scan = LaserScanData(np.ones(10), 1.0, -1.0, 0.01, 0.0, 10.0)
    with pytest.raises(ScanError, match="opposite sign") as err:
        scan_points(scan)
    assert err.value.kind == "angle_order"


@pytest.mark.parametrize("range_max", [1.0, 0.5])
def test_range_max_not_above_range_min_is_refused(range_max: float) -> None:
    with pytest.raises(ScanError, match="range_max") as err:
        scan_points(make_scan(np.ones(5), range_min=1.0, range_max=range_max))
    assert err.value.kind == "range_limits"


@pytest.mark.parametrize("field", ["angle_min", "angle_increment", "range_max"])
def test_non_finite_fields_are_refused(field: str) -> None:
    values = dict(
        ranges=np.ones(5),
        angle_min=0.0,
        angle_max=0.04,
        angle_increment=0.01,
        range_min=0.0,
        range_max=10.0,
    )
    values[field] = float("nan")
    with pytest.raises(ScanError, match=field):
        scan_points(LaserScanData(**values))


def test_a_scan_error_crosses_a_process_boundary_whole() -> None:
    # Raised in a worker process (a bench's pool, the back end's process) it comes back
    # pickled: kind, message and field intact, not a TypeError from __init__.
    import pickle

    from multi_robot_mapper.core.scan import ScanError

    error = pickle.loads(
        pickle.dumps(ScanError("angles", "angle_increment is 0", "angle_increment"))
    )
    assert (error.kind, error.message, error.field) == (
        "angles",
        "angle_increment is 0",
        "angle_increment",
    )
    assert str(error) == "angle_increment is 0"
