"""Every section of results.md says which MDP its runs measured: the engine and the RL step
limit each robot run recorded; runs saved before runs recorded them are the old step's."""
from __future__ import annotations

from qg_experiments.report.markdown import OLD_STEP, speed, step_label


def _run(**extra) -> dict:
    return {"rl_steps": 100, "wall_time": 10.0, "sim_time": 25.0, "step_timeouts": 40, **extra}


def test_a_run_names_its_engine_and_step_and_an_old_run_the_old_ones() -> None:
    assert OLD_STEP == ("pybullet", 0.25)
    assert step_label([_run()]) == "pybullet, step limit 0.25 s"
    assert step_label([_run(engine="mujoco", step_limit=3.0)]) == "mujoco, step limit 3 s"
    assert step_label([_run(engine="mujoco", step_limit=3.0), _run()]) == \
        "mujoco, step limit 3 s; pybullet, step limit 0.25 s"


def test_the_speed_line_of_robot_runs_starts_with_their_step_and_a_free_peg_has_none() -> None:
    line = speed([_run(engine="mujoco", step_limit=3.0)])
    assert line.startswith("mujoco, step limit 3 s; 100 RL steps in 0.2 worker-minutes")
    assert "250 ms simulated per step, 40% of steps ended by the step timeout" in line
    free_peg = speed([{"rl_steps": 100, "wall_time": 10.0}])      # no robot loop, no rest
    assert free_peg == "100 RL steps in 0.2 worker-minutes (10.00 steps/s)"


def test_the_speed_line_counts_cpu_time_when_every_run_has_it() -> None:
    """A sweep paused for a benchmark (or beside other work) took longer than it worked: the
    runs' CPU time is the worker time when all of them recorded it, the wall time beside."""
    paused = [{"rl_steps": 300, "wall_time": 120.0, "cpu_time": 30.0},
              {"rl_steps": 300, "wall_time": 120.0, "cpu_time": 30.0}]
    assert speed(paused) == ("600 RL steps in 1.0 worker-minutes of CPU (10.00 steps/s; 4.0 of "
                             "wall time)")
    older = [*paused, {"rl_steps": 600, "wall_time": 60.0}]        # saved before runs had it
    assert speed(older) == "1200 RL steps in 5.0 worker-minutes (4.00 steps/s)"
