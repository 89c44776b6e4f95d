"""The peg's paired comparison in results.md: per learning rate, paired by seed, Holm over the
learning rates, the Q spread across the seeds both algorithms ran, and the closing list's lines
beside the thesis's findings."""
from __future__ import annotations

import numpy as np
from qg_experiments.report.peg_sections import peg_paired, peg_pairs, peg_thesis_notes


def _run(algorithm: str, lr: float, seed: int, returns: list[float], q: float,
         mean_q: float = -50.0) -> dict:
    return {"spec": {"algorithm": algorithm, "lr": lr, "seed": seed, "gamma": 0.99},
            "episodes": [{"return": r, "mean_q": mean_q} for r in returns],
            "q_given": np.full((27, 11), q).tolist(), "q_pi": np.full(27, 2 * q).tolist()}


def _row(lines: list[str], lr: str) -> list[str]:
    (row,) = [line for line in lines if line.startswith(f"| {lr} |")]
    return [cell.strip() for cell in row.strip("|").split("|")]


def test_each_learning_rate_is_paired_by_seed_and_corrected_over_the_rates() -> None:
    rng = np.random.default_rng(0)
    results = []
    for seed in range(10):
        # lr 1e-3: QG-DDPG better on every seed, late and overall; lr 1e-2: a coin flip.
        base = rng.normal(-50.0, 5.0)
        results += [_run("ddpg", 1e-3, seed, [base - 10.0] * 8, q=seed,
                         mean_q=5e12 if seed < 3 else -111.0 if seed == 3 else -109.0),
                    _run("qgddpg", 1e-3, seed, [base] * 8, q=0.5 * seed)]
        noise = rng.normal(0.0, 1.0)
        results += [_run("ddpg", 1e-2, seed, [base] * 8, q=1.0),
                    _run("qgddpg", 1e-2, seed, [base + noise] * 8, q=1.0)]
    results.append(_run("ddpg", 1e-4, 0, [-80.0] * 8, q=0.0))   # no partner: not paired
    lines = peg_paired(peg_pairs(results, tail=2), tail=2)
    assert not any(line.startswith("| 0.0001 |") for line in lines)
    good = _row(lines, "0.001")
    assert good[1].startswith("10 (0, 1, 2")
    assert good[2] == "10 / 0 / 0" and good[5] == "10 / 0 / 0"
    assert good[3].startswith("10.00 [10.00, 10.00]")
    # exact two-sided Wilcoxon with 10 of 10 one way: 2 / 2^10; Holm over 2 rates doubles it
    assert float(good[4]) == float(good[7]) == np.float64(2 * 2 / 2 ** 10).round(5)
    assert good[8] == "1.44 / 2.87 (10 seeds)"  # the std over seeds 0..9, halved by QG's q
    assert good[9] == "297 of 297"
    assert good[10] == "0.5 [0.5, 0.5]"        # half of DDPG's on every resample of the seeds
    # 3 far outside [-100, 0]; -111 beyond its tenth (10), -109 within it: 4 diverged
    assert good[11] == "0 / 4"
    coin = _row(lines, "0.01")
    assert float(coin[4]) > 0.05
    assert coin[9] == "0 of 297"               # equal spreads: QG's is not smaller anywhere
    assert coin[10] == "n/a"                   # DDPG's spread is 0: no ratio


    # The closing list: each learning rate beside the thesis's findings, then where the gain is
    # largest, then the planned learning rate without pairs.
    curves = {("ddpg", lr): {"return_mean": np.array([-60.0 if lr == 1e-3 else -50.0])}
              for lr in (1e-3, 1e-2)}
    notes = peg_thesis_notes({"pairs": peg_pairs(results, tail=2), "curves": curves, "tail": 2,
                              "robot": "peg"}, planned_lrs=(1e-4, 1e-3, 1e-2))
    assert len(notes) == 4
    assert notes[1].startswith("- Peg, lr 0.001 (10 pairs): QG-DDPG's mean return over all "
                               "episodes higher in 10 of 10, 10.00 [10.00, 10.00]")
    assert ": QG-DDPG faster (thesis Fig. 8.2" in notes[1] and ": not worse (" in notes[1]
    # the actor's points: q_pi = 2 q, so its spread is twice the given actions' (0.5 q for QG)
    assert "given actions 1.44 / 2.87 (QG-DDPG's smaller at 297 of 297; ratio 0.5 [0.5, 0.5])" \
        in notes[1]
    assert "the actor's action 2.87 / 5.74 (QG-DDPG's smaller at 27 of 27; ratio 0.5 [0.5, " \
        "0.5])" in notes[1]
    assert ": not shown (thesis" in notes[0]
    assert "largest at lr 0.001 (+10.00); DDPG's mean return over all episodes is lowest at " \
           "lr 0.001 (-60.0)" in notes[2]
    assert notes[3] == "- Peg, lr 0.0001: no pairs yet."


def test_the_q_spread_is_over_the_seeds_whose_runs_both_hold_their_final_q() -> None:
    """Runs read back from their episode rows have no final Q: DDPG's whole on seeds 0-2,
    QG-DDPG's on 1-3, so both spreads are over seeds 1 and 2 only."""
    results = []
    for seed in range(5):
        for algorithm, whole, q in (("ddpg", seed <= 2, seed), ("qgddpg", 1 <= seed <= 3,
                                                                 0.5 * seed)):
            run = _run(algorithm, 1e-3, seed, [-100.0 + seed] * 4, q=q)
            if not whole:
                del run["q_given"], run["q_pi"]
            results.append(run)
    pairs = peg_pairs(results, tail=2)
    assert pairs.spread_seeds == {1e-3: [1, 2]}
    assert _row(peg_paired(pairs, tail=2), "0.001")[8] == "0.25 / 0.5 (2 seeds)"
    assert _row(peg_paired(pairs, tail=2), "0.001")[10] == "n/a"   # 2 seeds: no interval


def test_the_spread_ratios_interval_resamples_the_seeds_and_tells_narrower_from_alike() -> None:
    """Final Q drawn per seed: QG-DDPG's with half DDPG's spread, then with the same. The
    interval is below 1 for the first and holds 1 for the second; it holds its estimate."""
    from qg_experiments.report.peg_sections import q_spread_ratio
    rng = np.random.default_rng(3)

    def pairs(qg_scale: float) -> list[dict]:
        return [{"qgddpg": {"q_given": rng.normal(-50.0, qg_scale, (27, 11)).tolist()},
                 "ddpg": {"q_given": rng.normal(-50.0, 1.0, (27, 11)).tolist()}}
                for _ in range(10)]

    narrower, alike = q_spread_ratio(pairs(0.5)), q_spread_ratio(pairs(1.0))
    assert narrower.n == alike.n == 10
    assert 0.4 < narrower.mean < 0.6 and narrower.high < 1.0, narrower
    assert alike.low < 1.0 < alike.high and 0.9 < alike.mean < 1.1, alike
    for interval in (narrower, alike):
        assert interval.low <= interval.mean <= interval.high
    # the same data and generator seed, the same interval
    data = pairs(1.0)
    assert q_spread_ratio(data, resamples=500, seed=1) == q_spread_ratio(data, resamples=500,
                                                                         seed=1)


def test_no_pairs_no_table() -> None:
    pairs = peg_pairs([_run("ddpg", 1e-3, 0, [-1.0], q=0.0)], tail=1)
    assert pairs is None and peg_paired(pairs, tail=1) == []
    assert peg_thesis_notes({"pairs": None, "curves": {}, "tail": 1, "robot": "peg"}) == []


def test_the_td3_reference_says_what_a_maintained_agent_did() -> None:
    from qg_experiments.report.peg_sections import td3_reference_line
    line = td3_reference_line({"runs": [
        {"seed": 0, "steps": 20000, "tests": 20, "inserted": 20, "mean_return": -7.94},
        {"seed": 1, "steps": 20000, "tests": 20, "inserted": 17, "mean_return": -31.25}]})
    assert "after 20,000 training steps inserted 20 of 20, 17 of 20 fixed test starts" in line
    assert "(seeds 0, 1; mean return -7.9, -31.2)" in line


def test_the_first_insertion_per_run_and_its_median() -> None:
    from qg_experiments.report.peg_sections import _first_insertions

    def run(seed: int, successes: list[bool]) -> dict:
        return {"spec": {"algorithm": "qgddpg", "lr": 1e-4, "seed": seed},
                "episodes": [{"success": s} for s in successes]}
    def key(run: dict) -> tuple:
        return run["spec"]["algorithm"], run["spec"]["lr"]
    first = _first_insertions([run(2, [False] * 5), run(1, [False, False, True, True]),
                               run(0, [True] + [False] * 3)], key)
    assert first == {("qgddpg", 1e-4): "3 (1, 3, -)"}
    assert _first_insertions([run(0, [False]), run(1, [False])], key) \
        == {("qgddpg", 1e-4): "- (-, -)"}


def _random(kind: str, seed: int, returns: list[float]) -> dict:
    return {"label": f"random ({kind})", "spec": {"kind": kind, "seed": seed},
            "episodes": [{"return": r} for r in returns]}


def test_each_learner_is_paired_with_the_better_random_policy_on_its_seeds() -> None:
    from qg_experiments.report.peg_sections import peg_against_random
    results, randoms = [], []
    for seed in range(10):
        # uniform is the better random policy (-150 against -190); QG-DDPG beats it on every
        # seed, late by 100; DDPG beats it early only on seeds 0-4 and never late.
        randoms += [_random("noise", seed, [-190.0] * 10), _random("uniform", seed, [-150.0] * 10)]
        results += [_run("qgddpg", 1e-3, seed, [-150.0] * 8 + [-50.0] * 2, q=0.0),
                    _run("ddpg", 1e-3, seed, [-140.0 if seed < 5 else -160.0] * 8
                         + [-150.0] * 2, q=0.0)]
    results.append(_run("qgddpg", 1e-2, 42, [0.0] * 10, q=0.0))   # no random on seed 42
    lines = peg_against_random(results, randoms, tail=2)
    assert "random (uniform)" in lines[0]
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in lines
            if line.startswith("| 0.001 |")]
    assert [r[1] for r in rows] == ["QG-DDPG", "DDPG"]
    qg, ddpg = rows
    assert qg[2] == "10" and qg[3] == "10 / 0 / 0" and qg[6] == "10 / 0 / 0"
    assert qg[4].startswith("20.00 [20.00, 20.00]") and qg[7].startswith("100.00")
    # Holm over the 2 comparisons: 2 * 2 / 2^10
    assert float(qg[5]) == float(qg[8]) == np.float64(4 / 2 ** 10).round(5)
    assert ddpg[3] == "5 / 5 / 0" and ddpg[6] == "0 / 0 / 10" and float(ddpg[8]) == 1.0
    assert peg_against_random(results, [], tail=2) == []
