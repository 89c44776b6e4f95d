"""Sections 5 and 6 of ``docs/results.md``: the clearance-fit peg, free and on the simulated
Nextage; learning curves, the spread of Q across seeds, QG-DDPG against DDPG per learning rate
paired by seed, and what a maintained agent (SB3's TD3) does on the same free peg."""
from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import label

from qg_experiments import peg, stats
from qg_experiments.profile import PegBudget
from qg_experiments.report import plots
from qg_experiments.report.divergence import run_divergence
from qg_experiments.report.markdown import fmt, speed, table

__all__ = ["peg_section", "PegPairs", "peg_pairs", "q_spread_ratio", "per_pair", "peg_paired",
           "peg_against_random", "peg_thesis_notes", "peg_diverged", "peg_budget",
           "td3_reference_line", "TD3_REFERENCE"]

#: Per peg experiment: section heading, figure-name prefix, what moved the peg.
_PEG_PAGES = {
    "peg": ("## 5. Clearance-fit peg (free peg)", "exp5_peg",
            "Free peg (a drive constraint moves it; no arm)"),
    "nextage": ("## 6. The peg on the simulated Nextage, through the stack's cores", "exp6_nextage",
                "The Nextage arm (`robot:=sim_nextage`) through the stack's cores in one process "
                "(`experiments/nextage_peg.py`): the robot plugin, the bridge's 1 kHz position "
                "loop with its task-space IK and rest detector, and the executor's `PegTask`, "
                "read from the ROS nodes' config files; the same start positions as the free peg"),
}


def peg_section(results: list[dict[str, Any]], figures: Path, experiment: str = "peg",
                randoms: list[dict[str, Any]] | None = None,
                provenance: str = "") -> tuple[list[str], dict]:
    """The section of a peg experiment, and its curves and pairs for its lines beside the
    thesis (``peg_thesis_notes``; empty without runs).

    :param randoms: the random policies run on its seeds (``peg.run_peg_random``), in the
        table and the figure beside the learners.
    :param provenance: which runs these are, closing the section's first paragraph.
    """
    heading, prefix, robot = _PEG_PAGES[experiment]
    lines = [heading, ""]
    if not results:
        return lines + ["Not run in this profile.", ""], {}
    randoms = randoms or []
    curves = peg.learning_curves(results)
    random_curves = peg.random_curves(randoms)
    spread, spread_seeds = peg.q_spread(results), peg.q_seeds(results)
    spec = results[0]["spec"]
    tail = max(1, spec["episodes"] // 5)
    window = 5 if spec["episodes"] >= 20 else 1
    plots.peg_learning(curves, window, figures / f"{prefix}_learning.png", random_curves)
    if spread:
        plots.q_spread({points: peg.q_spread(results, points) for points in peg.Q_POINTS},
                       figures / f"{prefix}_q_std.png", spread_seeds)
    first = _first_insertions(results, lambda r: (r["spec"]["algorithm"], r["spec"]["lr"]))
    first_random = _first_insertions(randoms, lambda r: r["label"])

    def row(name: str, lr: str, c: dict[str, Any], first: str, s: np.ndarray | None = None,
            n: int = 0) -> list[str]:
        return [name, lr, str(c["seeds"]), first,
                fmt(float(np.mean(c["return_mean"][-tail:])), 1),
                f"{float(np.mean(c['success_mean'][-tail:])):.0%}",
                fmt(float(np.mean(c["steps_mean"][-tail:])), 0),
                "n/a" if s is None else f"{fmt(float(np.median(s)), 3)} ({n} seeds)"]

    rows = [row(label(a), f"{lr:g}", c, first[(a, lr)], spread.get((a, lr)),
                spread_seeds.get((a, lr), 0)) for (a, lr), c in curves.items()]
    rows += [row(name, "-", c, first_random[name]) for name, c in random_curves.items()]
    lines += [f"{robot}. {spec['episodes']} episodes of at most {spec['episode_steps']} steps "
              f"per run, {spec['train_iterations']} minibatch updates after each episode (thesis: "
              "50 epochs x up to 15 minibatches, 300 episodes, 10 seeds). Networks 3 x 200, no "
              f"target networks (the thesis's initialisation: the actor He-uniform, the "
              f"critic's weights from N(0, 0.001)), actor lr = critic lr, exploration noise on "
              f"every step. Speed: {speed(results)}."
              + (" Beside them, random policies on the same seeds, which meet the same starts "
                 "and learn nothing: " + "; ".join(
                     f"{r['label']}, {peg.PEG_RANDOM_KINDS[r['spec']['kind']]}"
                     for r in {r["label"]: r for r in randoms}.values()) + "."
                 if randoms else "") + (f" {provenance}" if provenance else ""),
              "",
              f"![{experiment} learning curves](figures/{prefix}_learning.png)", ""]
    if spread:
        lines += [f"![{experiment} Q spread](figures/{prefix}_q_std.png)", ""]
    lines += table(["algorithm", "lr", "seeds", "first inserted in episode (median; each seed)",
                    f"mean return, last {tail} episodes",
                    "success, last episodes", "steps, last episodes",
                    "median std of Q (27 x 11)"], rows)
    reference = figures.parent / "data" / TD3_REFERENCE
    if experiment == "peg" and reference.is_file():
        lines += ["", td3_reference_line(json.loads(reference.read_text()))]
    return lines + [""], {"curves": curves, "pairs": peg_pairs(results, tail), "tail": tail,
                          "robot": experiment}


def _first_insertions(results: list[dict[str, Any]], key: Any) -> dict[Any, str]:
    """Per ``key(run)`` ((algorithm, lr), or a random policy's label): the episode (from 1) of
    each run's first insertion, seed by seed, with their median; "-" for a run that never
    inserted (the median counts it as the last)."""
    firsts: dict[Any, list[tuple[int, float]]] = {}
    for r in sorted(results, key=lambda r: r["spec"]["seed"]):
        episode = next((k + 1 for k, e in enumerate(r["episodes"]) if e["success"]), np.inf)
        firsts.setdefault(key(r), []).append((r["spec"]["seed"], episode))

    def episode(e: float) -> str:
        return "-" if e == np.inf else f"{e:.0f}"

    return {key: f"{episode(float(np.median([e for _, e in runs])))} ("
                 + ", ".join(episode(e) for _, e in runs) + ")"
            for key, runs in firsts.items()}


#: ``benchmarks/peg_td3_reference.py``'s numbers, in ``docs/data``.
TD3_REFERENCE = "peg_td3_reference.json"


def td3_reference_line(reference: dict[str, Any]) -> str:
    """What a maintained agent does on the same free peg (whether it can be learned at all)."""
    runs = reference["runs"]
    inserted = ", ".join(f"{r['inserted']} of {r['tests']}" for r in runs)
    returns = ", ".join(f"{r['mean_return']:.1f}" for r in runs)
    steps = sorted({r["steps"] for r in runs})
    return (f"The same environment with a maintained agent (`benchmarks/peg_td3_reference.py`, "
            f"`QGPeg-v0`): Stable-Baselines3's TD3 with its defaults (two 400-300 critics with "
            f"target networks, a delayed actor, one update per step), the same exploration "
            f"noise and discount, after {' / '.join(f'{n:,}' for n in steps)} training steps "
            f"inserted {inserted} fixed test starts with its deterministic actor (seeds "
            f"{', '.join(str(r['seed']) for r in runs)}; mean return {returns}).")


def per_pair(results: list[dict[str, Any]], value: Any) -> dict[float, dict[int, dict]]:
    """lr -> seed -> algorithm -> ``value(run)``, for the (lr, seed) pairs both algorithms ran."""
    runs: dict[float, dict[int, dict[str, Any]]] = {}
    for r in results:
        s = r["spec"]
        runs.setdefault(s["lr"], {}).setdefault(s["seed"], {})[s["algorithm"]] = value(r)
    return {lr: {seed: v for seed, v in sorted(seeds.items()) if {"qgddpg", "ddpg"} <= set(v)}
            for lr, seeds in sorted(runs.items(), reverse=True)}


def _mean_return(episodes: slice) -> Any:
    return lambda run: float(np.mean([e["return"] for e in run["episodes"][episodes]]))


def _measures(tail: int) -> dict[str, Any]:
    """The two per-run measures both paired tables compare: the mean return over all episodes
    (how fast the run learned) and over the last ``tail`` (where it got to)."""
    return {"all": _mean_return(slice(None)), "late": _mean_return(slice(-tail, None))}


def _paired_cells(c: stats.PairedComparison, p: float) -> list[str]:
    """A paired comparison's cells: wins of each side and ties, the difference with its 95 %
    interval, the (Holm-corrected) p."""
    return [f"{c.wins_a} / {c.wins_b} / {c.ties}", stats.format_interval(c.difference, 2),
            f"{p:.3g}"]


def peg_diverged(run: dict[str, Any]) -> bool:
    """Whether the run's critic diverged: its mean Q after some episode's updates left the
    realisable range of the peg's rewards ([-1, 0] a step, so [-1 / (1 - gamma), 0]) by more
    than the grid's margin (``report.divergence``, at the run's own discount)."""
    return run_divergence(run, run["spec"]["gamma"])[0]


@dataclass(frozen=True)
class PegPairs:
    """QG-DDPG against DDPG per learning rate, on the seeds both ran (``peg_pairs``).

    :param lrs: the learning rates with pairs, largest first.
    :param compared: per measure (``_measures``: ``all``, ``late``) and lr, the paired
        comparison (QG-DDPG as A: a positive difference is QG-DDPG's higher return).
    :param holm: the same, its Wilcoxon p Holm-corrected over the learning rates.
    :param diverged: lr -> seed -> algorithm -> whether the critic diverged.
    :param spread: per set of points (``peg.Q_POINTS``) and (algorithm, lr), the std of the
        final Q across the paired seeds.
    :param spread_seeds: per lr, the paired seeds whose runs hold their final Q (the spread's).
    :param spread_ratio: per set of points and lr, QG-DDPG's median spread over DDPG's with
        its interval over those seeds (``q_spread_ratio``; lrs with ``RATIO_SEEDS`` of them).
    """
    lrs: list[float]
    compared: dict[str, dict[float, stats.PairedComparison]]
    holm: dict[str, dict[float, float]]
    diverged: dict[float, dict[int, dict[str, bool]]]
    spread: dict[str, dict[tuple[str, float], np.ndarray]]
    spread_seeds: dict[float, list[int]]
    spread_ratio: dict[str, dict[float, stats.Interval]]

    def spreads(self, lr: float, points: str = "given") -> dict[str, np.ndarray] | None:
        """QG-DDPG's and DDPG's spread at ``lr``, or None (fewer than two paired seeds)."""
        spread = self.spread[points]
        return ({alg: spread[(alg, lr)] for alg in ("qgddpg", "ddpg")}
                if ("ddpg", lr) in spread and ("qgddpg", lr) in spread else None)


def peg_pairs(results: list[dict[str, Any]], tail: int) -> PegPairs | None:
    """QG-DDPG against DDPG on the same seeds, learning rate by learning rate (the thesis's
    claim is per learning rate): each run's mean return over all episodes (how fast it learned:
    the area under its learning curve) and over the last ``tail`` (where it got to), Wilcoxon
    signed-rank over the seeds, Holm over the learning rates; divergence; and the thesis's
    second claim, the spread of the final Q across seeds. None without a pair."""
    measures = {name: per_pair(results, measure) for name, measure in _measures(tail).items()}
    lrs = [lr for lr, pairs in measures["all"].items() if pairs]
    if not lrs:
        return None
    compared = {name: {lr: stats.paired_comparison(
        [-pairs[lr][seed]["qgddpg"] for seed in pairs[lr]],
        [-pairs[lr][seed]["ddpg"] for seed in pairs[lr]]) for lr in lrs}
        for name, pairs in measures.items()}   # negated: paired_comparison's lower is better
    holm = {name: dict(zip(lrs, stats.holm([c[lr].wilcoxon_p for lr in lrs]), strict=True))
            for name, c in compared.items()}
    diverged = per_pair(results, peg_diverged)
    # The spread across the seeds on which both algorithms' runs hold their final Q
    # (``peg.q_spread``: two seeds at least; all a sweep saves, not runs read back from their
    # episode rows, ``episode_rows``), so that both spreads are over the same seeds.
    whole = per_pair(list(filter(peg.holds_final_q, results)), lambda run: run)
    paired = [run for lr in lrs for runs in whole.get(lr, {}).values() for run in runs.values()]
    seeds = {lr: sorted(whole.get(lr, {})) for lr in lrs}
    ratio = {points: {lr: q for lr in lrs if len(seeds[lr]) >= RATIO_SEEDS
                      and (q := q_spread_ratio(list(whole[lr].values()), points)) is not None}
             for points in peg.Q_POINTS}
    return PegPairs(lrs, compared, holm, diverged,
                    {points: peg.q_spread(paired, points) for points in peg.Q_POINTS}, seeds,
                    ratio)


#: Paired seeds holding their final Q that a spread ratio's interval needs (the report's
#: least number of seeds for a claim).
RATIO_SEEDS = 5


def q_spread_ratio(pairs: list[dict[str, dict[str, Any]]], points: str = "given",
                   resamples: int = stats.RESAMPLES, seed: int = 0) -> stats.Interval | None:
    """QG-DDPG's median Q spread over DDPG's (thesis Fig. 8.3: below 1 if the graph narrows
    it), with a 95 % percentile bootstrap interval that resamples the seeds.

    A spread is a property of a set of seeds, not of one run, so the seeds are what is
    resampled, the same resample for both algorithms (they are paired by seed): the interval
    says how much the ratio owes to which seeds ran.
    :param pairs: per seed, algorithm -> run holding its final Q (``peg.holds_final_q``).
    :returns: the ratio (as the interval's ``mean``) and its interval over ``n`` seeds; None if
        DDPG's spread is 0.
    """
    field = peg.Q_POINTS[points]
    q = {alg: np.array([np.ravel(pair[alg][field]) for pair in pairs], dtype=float)
         for alg in ("qgddpg", "ddpg")}

    def ratio(rows: np.ndarray) -> np.ndarray:
        """The ratio for each resample (a row of seed indices)."""
        median = {alg: np.median(v[rows].std(axis=-2), axis=-1) for alg, v in q.items()}
        with np.errstate(divide="ignore", invalid="ignore"):
            return median["qgddpg"] / median["ddpg"]

    whole = np.arange(len(pairs))
    estimate = float(ratio(whole))
    if not np.isfinite(estimate):
        return None
    rng = np.random.default_rng(seed)
    draws = np.concatenate([ratio(rng.integers(0, len(pairs), (min(1000, left), len(pairs))))
                            for left in range(resamples, 0, -1000)])
    # (a resample of one seed drawn every time has no spread, 0 / 0: left out)
    low, high = np.nanpercentile(draws, [50 * (1 - stats.CONFIDENCE),
                                         50 * (1 + stats.CONFIDENCE)])
    return stats.Interval(estimate, float(low), float(high), len(pairs))


def _ratio_cell(interval: stats.Interval | None) -> str:
    """``q_spread_ratio``'s ratio and interval for a table or a line."""
    return "n/a" if interval is None else \
        f"{interval.mean:.3g} [{interval.low:.3g}, {interval.high:.3g}]"


def peg_paired(pairs: PegPairs | None, tail: int) -> list[str]:
    """The table of ``peg_pairs``: per learning rate both measures' wins, differences and p,
    the median Q spread (given actions) with the points where QG-DDPG's is the smaller, and the
    diverged critics."""
    if pairs is None:
        return []
    rows = []
    for lr in pairs.lrs:
        a, b = pairs.compared["all"][lr], pairs.compared["late"][lr]
        seeds = pairs.diverged[lr]
        q = pairs.spreads(lr)
        rows.append([f"{lr:g}", f"{a.n} ({', '.join(str(s) for s in seeds)})",
                     *_paired_cells(a, pairs.holm["all"][lr]),
                     *_paired_cells(b, pairs.holm["late"][lr]),
                     "n/a" if q is None else
                     f"{np.median(q['qgddpg']):.3g} / {np.median(q['ddpg']):.3g} "
                     f"({len(pairs.spread_seeds[lr])} seeds)",
                     "n/a" if q is None else
                     f"{int(np.sum(q['qgddpg'] < q['ddpg']))} of {q['ddpg'].size}",
                     _ratio_cell(pairs.spread_ratio["given"].get(lr)),
                     " / ".join(str(sum(runs[alg] for runs in seeds.values()))
                                for alg in ("qgddpg", "ddpg"))])
    return [f"QG-DDPG against DDPG per learning rate, paired by seed (the seeds both ran). "
            f"*All*: each run's mean return over all its episodes (the area under its learning "
            f"curve: how fast it learned); *late*: over its last {tail}. QG-DDPG higher / DDPG "
            f"higher / ties; QG-DDPG minus DDPG with its 95 % interval; two-sided Wilcoxon "
            f"signed-rank p, Holm-corrected over the {len(pairs.lrs)} learning rates (with n "
            f"pairs the smallest p is 2 / 2^n: 0.0625 for 5, 0.002 for 10). Q spread: the "
            f"standard deviation across those seeds of each of the 27 x 11 final Q predictions "
            f"(thesis Fig. 8.3), its median QG-DDPG / DDPG over the paired seeds whose runs "
            f"hold their final Q (how many), the points where QG-DDPG's is smaller, and QG-DDPG's "
            f"median over DDPG's with its 95 % interval from resampling those seeds (given "
            f"{RATIO_SEEDS} of them at least; below 1: the graph narrows the spread). "
            f"Diverged: the runs whose mean Q after an episode's updates left "
            f"[-1 / (1 - gamma), 0] by more than a tenth of its width (as the grid's).",
            "", *table(["lr", "pairs (seeds)", "all: QG / DDPG / ties", "all: QG - DDPG [95 % CI]",
                        "all: p (Holm)", "late: QG / DDPG / ties", "late: QG - DDPG [95 % CI]",
                        "late: p (Holm)", "median Q spread QG / DDPG",
                        "QG spread smaller", "spread QG / DDPG [95 % CI]",
                        "diverged QG / DDPG"], rows)]


def peg_against_random(results: list[dict[str, Any]], randoms: list[dict[str, Any]],
                       tail: int) -> list[str]:
    """Each learner against the best random policy on the same seeds, which met the same starts
    (``peg.run_peg_random``): whether it learned anything at all, per learning rate.

    The best random policy is the one with the higher mean return over all its episodes and
    seeds (as the Panda's bar is the best random setting). The measures and tests are
    ``peg_paired``'s, Holm-corrected over every (learning rate, algorithm).
    """
    by_kind: dict[str, dict[int, dict[str, Any]]] = {}
    for r in randoms:
        by_kind.setdefault(r["spec"]["kind"], {})[r["spec"]["seed"]] = r
    if not by_kind or not results:
        return []
    measures = _measures(tail)
    everything = measures["all"]
    best = by_kind[max(sorted(by_kind), key=lambda kind: np.mean(
        [everything(r) for r in by_kind[kind].values()]))]
    runs: dict[tuple[float, str], dict[int, dict[str, Any]]] = {}
    for r in results:
        s = r["spec"]
        if s["seed"] in best:
            runs.setdefault((s["lr"], s["algorithm"]), {})[s["seed"]] = r
    keys = sorted(runs, key=lambda k: (-k[0], k[1] != "qgddpg"))
    if not keys:
        return []
    compared = {name: [stats.paired_comparison(   # negated: paired_comparison's lower is better
        [-measure(runs[key][seed]) for seed in sorted(runs[key])],
        [-measure(best[seed]) for seed in sorted(runs[key])]) for key in keys]
        for name, measure in measures.items()}
    holm = {name: stats.holm([c.wilcoxon_p for c in tests]) for name, tests in compared.items()}
    rows = []
    for i, (lr, algorithm) in enumerate(keys):
        a, b = compared["all"][i], compared["late"][i]
        rows.append([f"{lr:g}", label(algorithm), str(a.n),
                     *_paired_cells(a, holm["all"][i]), *_paired_cells(b, holm["late"][i])])
    name = next(iter(best.values()))["label"]
    return [f"Each learner against the better random policy, {name} (the higher mean return "
            f"over all episodes), on the same seeds, which met the same starts: the bar a "
            f"learner has to clear to have learned anything. The measures and tests are the "
            f"table's above; learner higher / random higher / ties, learner minus random, "
            f"Holm over the {len(keys)} learner-and-learning-rate comparisons.", "",
            *table(["lr", "learner", "pairs", "all: learner / random / ties",
                    "all: learner - random [95 % CI]", "all: p (Holm)",
                    "late: learner / random / ties", "late: learner - random [95 % CI]",
                    "late: p (Holm)"], rows)]


#: How the lines beside the thesis name the peg's two sets of Q points (``peg.Q_POINTS``).
_POINTS = {"given": "given actions", "pi": "the actor's action"}


def peg_thesis_notes(data: dict[str, Any], planned_lrs: Iterable[float] = ()) -> list[str]:
    """A peg experiment's lines beside the thesis: per learning rate, QG-DDPG against DDPG
    paired by seed (``peg_pairs``) beside the thesis's ch. 8.3.2 findings (Figs. 8.2 and 8.3
    show curves and boxes; its text gives no numbers); then where the gain is largest, and the
    learning rates of ``planned_lrs`` without pairs yet."""
    pairs: PegPairs | None = data.get("pairs")
    if pairs is None:
        return []
    robot = "Peg" if data["robot"] == "peg" else "Nextage peg"
    notes = []
    for lr in pairs.lrs:
        overall, late = pairs.compared["all"][lr], pairs.compared["late"][lr]
        p_speed, p_late = pairs.holm["all"][lr], pairs.holm["late"][lr]
        faster = ("not shown" if p_speed >= 0.05
                  else "QG-DDPG faster" if overall.difference.mean > 0 else "DDPG faster")
        worse = p_late < 0.05 and late.difference.mean < 0
        text = (f"- {robot}, lr {lr:g} ({overall.n} pairs): QG-DDPG's mean return over all "
                f"episodes higher in {overall.wins_a} of {overall.n}, "
                f"{stats.format_interval(overall.difference, 2)}, p (Holm) = {p_speed:.3g}: "
                f"{faster} (thesis Fig. 8.2: faster at every learning rate); over the last "
                f"{data['tail']} episodes {stats.format_interval(late.difference, 2)}, "
                f"p = {p_late:.3g}: "
                f"{'worse' if worse else 'not worse'} (thesis: never worse)")
        spreads = [(points, pairs.spreads(lr, points)) for points in ("given", "pi")]
        if all(q is not None for _, q in spreads):
            seeds = ", ".join(map(str, pairs.spread_seeds[lr]))
            text += f"; median Q spread across seeds {seeds} QG-DDPG / DDPG: " + ", ".join(
                f"{_POINTS[points]} {np.median(q['qgddpg']):.3g} / {np.median(q['ddpg']):.3g} "
                f"(QG-DDPG's smaller at {int(np.sum(q['qgddpg'] < q['ddpg']))} of "
                f"{q['ddpg'].size}"
                + (f"; ratio {_ratio_cell(r)}"
                   if (r := pairs.spread_ratio[points].get(lr)) is not None else "")
                + ")" for points, q in spreads) + \
                " (thesis Fig. 8.3, lr 1e-4: clearly smaller with QG-DDPG)"
        notes.append(text + ".")
    if len(pairs.lrs) > 1:
        gain = {lr: pairs.compared["all"][lr].difference.mean for lr in pairs.lrs}
        ddpg = {lr: float(np.mean(data["curves"][("ddpg", lr)]["return_mean"]))
                for lr in pairs.lrs}
        best, poorest = max(gain, key=gain.get), min(ddpg, key=ddpg.get)
        notes.append(f"- {robot}: QG-DDPG's gain over all episodes is largest at lr {best:g} "
                     f"({gain[best]:+.2f}); DDPG's mean return over all episodes is lowest at "
                     f"lr {poorest:g} ({ddpg[poorest]:.1f}) (thesis: the gain is largest where "
                     f"DDPG does poorly, at lr 1e-4 of its three).")
    missing = [lr for lr in planned_lrs if lr not in pairs.lrs]
    if missing:
        notes.append(f"- {robot}, lr {', '.join(f'{lr:g}' for lr in missing)}: no pairs yet.")
    return notes


def peg_budget(budget: PegBudget) -> str:
    """A peg budget in words, for the budget table."""
    return (f"{budget.episodes} episodes x {len(budget.seeds)} seeds, {len(budget.lrs)} lrs, "
            f"{budget.train_iterations} updates/episode")

