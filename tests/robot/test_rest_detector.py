"""Rest detector: hold time, minimum and maximum step duration."""
from __future__ import annotations

import pytest
from robot_bridge_node.core.rest_detector import RestConfig, RestDetector

DT = 0.001


def ticks_until_done(detector: RestDetector, speeds: list[tuple[float, float]]) -> int:
    for i, (v, w) in enumerate(speeds, start=1):
        if detector.update(v, w, DT):
            return i
    return -1


def test_fires_after_the_hold_time_of_stillness() -> None:
    detector = RestDetector()
    moving = [(0.01, 0.0)] * 100
    still = [(0.001, 0.01)] * 100
    assert ticks_until_done(detector, moving + still) == 120  # 100 moving + 20 ms quiet
    assert detector.at_rest and not detector.timed_out


@pytest.mark.parametrize("speeds", [(0.0021, 0.0), (0.0, 0.021)])
def test_either_speed_above_threshold_keeps_the_step_running(speeds: tuple[float, float]) -> None:
    detector = RestDetector()
    limit = round(detector.config.max_time / DT)
    assert limit == 3000     # the default step ends at rest; 3 s is its safety bound
    assert ticks_until_done(detector, [speeds] * (limit - 1)) == -1
    assert detector.update(*speeds, DT)  # the 3000th ms: maximum step time
    assert detector.timed_out and not detector.at_rest


def test_minimum_time_holds_back_an_early_rest() -> None:
    detector = RestDetector(RestConfig(hold_time=0.005, min_time=0.05))
    assert ticks_until_done(detector, [(0.0, 0.0)] * 100) == 50
    detector.reset()
    assert detector.elapsed == 0.0 and not detector.at_rest


def test_a_twitch_restarts_the_hold_time() -> None:
    detector = RestDetector()
    speeds = [(0.0, 0.0)] * 15 + [(0.01, 0.0)] + [(0.0, 0.0)] * 30
    assert ticks_until_done(detector, speeds) == 36


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="hold_time"):
        RestConfig(hold_time=1.0, max_time=0.5)
    with pytest.raises(ValueError, match="linear_threshold"):
        RestConfig(linear_threshold=0.0)
    with pytest.raises(ValueError, match="unknown"):
        RestConfig.from_dict({"hold": 0.02})
