"""The report's verdict per setting (section 7b): Holm over the settings, equivalence by TOST."""
from __future__ import annotations

import numpy as np
from qg_experiments.profile import Statistics
from qg_experiments.report.aggregate_section import judge, verdict_sentence


def _run(algorithm: str, lr: float, seed: int, steps: float) -> dict:
    spec = {"algorithm": algorithm, "critic_lr": lr, "iterations": 50, "reward": "dense",
            "replay_capacity": None, "gamma": None, "observation": None, "seed": seed}
    return {"spec": spec, "episodes": [{"mode": "test", "steps": steps}]}


def _setting(shift: float, noise: float) -> list[dict]:
    """8 cells x 5 seeds; QG-DDPG needs ``shift`` fewer steps than DDPG, give or take noise."""
    rng = np.random.default_rng(int(shift * 10))
    runs = []
    for cell in range(8):
        for seed in range(5):
            ddpg = 60.0 + 10 * cell + rng.normal(0, 5)
            runs += [_run("ddpg", 10.0 ** -cell, seed, ddpg),
                     _run("qgddpg", 10.0 ** -cell, seed, ddpg - shift + rng.normal(0, noise))]
    return runs


def test_each_setting_gets_a_verdict_and_the_family_is_holm_corrected() -> None:
    statistics = Statistics(level=0.05, equivalence_margin=10.0)
    judged = {j.setting: j for j in judge({"better": _setting(20.0, 2.0),
                                           "same": _setting(0.0, 2.0),
                                           "unclear": _setting(0.0, 40.0)}, statistics)}
    assert {s: j.verdict for s, j in judged.items()} == {
        "better": "A better", "same": "equivalent", "unclear": "undecided"}
    # Holm over three settings: the smallest p times 3, the others at least as large as it.
    smallest = min(j.comparison.wilcoxon_p for j in judged.values())
    assert judged["better"].difference_p == smallest * 3
    assert "**QG-DDPG needs fewer test steps**" in verdict_sentence(judged["better"], statistics)
    assert "**equivalent within ±10 test steps**" in verdict_sentence(judged["same"], statistics)
    unclear = verdict_sentence(judged["unclear"], statistics)
    assert "**undecided**" in unclear
    # ... and says how many pairs its spread would need (40 pairs, noise 40: sd about 40).
    j = judged["unclear"]
    assert 30 < j.spread < 50 and j.pairs_needed > 40
    assert f"spread by {j.spread:.1f} steps" in unclear and f"about {j.pairs_needed:.0f} pairs" \
        in unclear
