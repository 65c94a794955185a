"""A short goal-covering scenario the tests share: two straight paths, one second of warm-up."""

import pytest

SHORT_SCENARIO = """
field = "spl"
noise = "default"
runs = 1
ball_speed = 0.4
deliberative_hz = [1.0]
reactive_hz = 57.0
warmup = 1.0
settle = 0.5
sample_period = 0.05
keeper_start = [-2.55, 0.0, 0.0]
reference = "value-function"
target_pose_error = 0.10

[[methods]]
name = "value-function"
team = "full"

[[trajectories]]
name = "across"
waypoints = [[-1.0, -1.0], [-1.0, 1.0]]

[[trajectories]]
name = "toward"
waypoints = [[0.0, 0.5], [-1.5, 0.0]]
"""


@pytest.fixture
def short_scenario() -> str:
    return SHORT_SCENARIO
