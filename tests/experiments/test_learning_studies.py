"""The studies behind docs/learning.md run what their names say, on the thesis profile."""
from qg_experiments.learning_studies import study_specs


def test_the_cap_study_is_the_starved_cell_with_the_thesis_training_cap():
    specs = study_specs("thesis")
    cap = specs["cap"]
    assert [s.seed for s in cap] == [0, 1, 2]
    assert {(s.algorithm, s.critic_lr, s.iterations, s.train_max_steps, s.experiment)
            for s in cap} == {("qgddpg", 1e-4, 10, 1000, "cap")}
    # Everything else is the grid's protocol: 40 training and 8 test episodes, test cap 200.
    grid_run = next(s for s in specs["graph"] if s.algorithm == "qgddpg" and s.seed == 0
                    and not s.graph_resolution)
    assert grid_run.train_max_steps == 50
    assert {(s.train_episodes, s.test_episodes, s.test_max_steps, s.observation) for s in cap} \
        == {(grid_run.train_episodes, grid_run.test_episodes, grid_run.test_max_steps,
             grid_run.observation)}


def test_the_studies_keep_the_tilt_state_and_the_echo_study_compares_three_states():
    """The first five studies stay on the 6-D state they were measured with, whatever the grid
    uses; the echo study runs the stalling cell with each tilt state, 3 seeds each."""
    specs = study_specs("thesis")
    for name in ("observation", "graph", "housing", "schedule", "cap"):
        expected = {"thesis"} if name == "observation" else {"tilt"}
        assert {s.observation for s in specs[name]} == expected, name
    echo = specs["echo"]
    assert sorted((s.observation, s.seed) for s in echo) == sorted(
        (state, seed) for state in ("tilt", "tilt_force", "tilt_only") for seed in (0, 1, 2))
    assert {(s.algorithm, s.critic_lr, s.iterations, s.train_max_steps, s.test_max_steps)
            for s in echo} == {("qgddpg", 1e-3, 10, 50, 200)}
