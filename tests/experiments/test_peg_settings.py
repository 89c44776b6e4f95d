"""The peg experiments keep their own discount: learner.yaml's is tuned to the Panda task."""
from __future__ import annotations

from qg_common.params import config_file, load_ros_params
from qg_experiments.peg import peg_specs
from qg_experiments.profile import PegBudget, load_profile


def test_peg_runs_take_the_budgets_discount_not_the_panda_learners():
    panda_gamma = load_ros_params(config_file("learner.yaml"), "learner")["learner"]["ddpg"][
        "gamma"]
    thesis = load_profile("thesis")
    assert thesis.peg.gamma == thesis.nextage.gamma == 0.99 != panda_gamma
    specs = peg_specs(PegBudget(lrs=(1e-3, 1e-4), seeds=(0, 1), gamma=0.95))
    assert len(specs) == 8 and {s.gamma for s in specs} == {0.95}
