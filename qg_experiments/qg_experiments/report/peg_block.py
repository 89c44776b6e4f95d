"""Sections 5 and 6 of ``docs/results.md`` as one block between markers, so that they can be
written again alone (``python -m qg_experiments.peg_report``) while the page's other sections
keep the runs they were written from.

A thesis-budget peg sweep takes days of a core and spans sessions; its sections show where it
stands without the page's other experiments, whose runs are not its own (and may be gone), being
run again. Each peg run reported is its saved JSON or, when a reset machine took that, its
episode rows from the CSV beside the page (``episode_rows``): every number of the sections comes
from one of the two, and the sections say how many runs each gave and over which seeds the final
Q (only in whole runs) is.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from qg_experiments import peg
from qg_experiments.episode_rows import ROWS, runs_from_rows, with_rows
from qg_experiments.profile import PegBudget, Profile
from qg_experiments.report.markdown import PEG_BLOCK, code_label
from qg_experiments.report.peg_sections import (
    peg_against_random,
    peg_paired,
    peg_section,
    peg_thesis_notes,
)
from qg_experiments.report.tables import episodes_csv
from qg_experiments.tasks import saved_result
from qg_experiments.tensorboard_log import export_runs

__all__ = ["PEG_EXPERIMENTS", "peg_budget_of", "peg_specs_of", "peg_runs", "peg_rows",
           "peg_block"]

#: The peg experiments, each with the robot that moves its peg (``peg.PEG_ROBOTS``).
PEG_EXPERIMENTS = {experiment: robot for robot, experiment in peg.PEG_ROBOTS.items()}


def peg_budget_of(profile: Profile, experiment: str) -> PegBudget | None:
    """The profile's budget of a peg experiment (``peg``, ``nextage``), None if it has none."""
    return profile.peg if experiment == "peg" else profile.nextage


def peg_specs_of(profile: Profile, experiment: str, config_dir: str | None = None
                 ) -> tuple[list[Any], list[Any]]:
    """The learners' and the random policies' specs of a peg experiment of ``profile``."""
    budget, robot = peg_budget_of(profile, experiment), PEG_EXPERIMENTS[experiment]
    if budget is None:
        return [], []
    return (peg.peg_specs(budget, config_dir, robot),
            peg.peg_random_specs(budget, config_dir, robot))


def _groups(profile: Profile, experiment: str, config_dir: str | None
            ) -> list[tuple[str, list[Any]]]:
    """(where its runs are saved, specs) of a peg experiment's learners, then its random
    policies."""
    return list(zip((experiment, peg.random_experiment(experiment)),
                    peg_specs_of(profile, experiment, config_dir), strict=True))


def peg_runs(profile: Profile, out: Path, docs: Path, experiment: str,
             config_dir: str | None = None
             ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The learners' and the random policies' runs of a peg experiment of ``profile``: each
    one's saved run under ``out`` or, when it has none, its episode rows in ``docs``'s data.
    A saved run or rows of another setting (``run_identity``) are not one of them."""
    data = Path(docs) / "data" / profile.name
    learners, randoms = (
        with_rows([run for spec in specs if (run := saved_result(out, spec)) is not None],
                  data / f"{name}_episodes.csv", specs)
        for name, specs in _groups(profile, experiment, config_dir))
    return learners, randoms


def peg_rows(profile: Profile, docs: Path, config_dir: str | None = None) -> set[str]:
    """The names of the profile's peg runs (learners and random policies) whose every episode
    the rows beside the page hold: the runs its peg sections report without their JSON."""
    data = Path(docs) / "data" / profile.name
    return {run["name"] for experiment in PEG_EXPERIMENTS
            for name, specs in _groups(profile, experiment, config_dir)
            for run in runs_from_rows(data / f"{name}_episodes.csv", specs)}


def _provenance(profile_name: str, results: list[dict[str, Any]],
                randoms: list[dict[str, Any]], planned: tuple[int, int]) -> str:
    """Which runs the section reports, and what each gave: the runs finished against the
    budget, how many were read back from their episode rows, the commits and config digests."""
    runs = [*results, *randoms]
    rows = [r for r in runs if r.get("source") == ROWS]
    whole = [r for r in runs if r.get("source") != ROWS]
    text = (f"Runs finished: {len(results)} of {planned[0]} learners, {len(randoms)} of "
            f"{planned[1]} random policies.")
    if rows:
        text += (f" {len(rows)} of them are read back from their episode rows (the CSVs in "
                 f"[`data/{profile_name}/`](data/{profile_name}/), "
                 f"`qg_experiments/episode_rows.py`): their JSON went with a reset machine, and "
                 f"runs are deterministic per seed. Rows hold every episode's steps, insertion, "
                 f"return and mean Q, not the run's final Q, timing or commit.")
    if whole:
        digests = sorted({str(r.get("config_digest", "?")) for r in whole})
        text += (f" The {len(whole)} whole runs: config digest(s) "
                 f"{', '.join(f'`{d}`' for d in digests)}; made at {code_label(whole)}.")
    return (text + f" The peg's sections are written with the page, and alone, as a sweep's "
            f"runs come in, by `python -m qg_experiments.peg_report --profile {profile_name}`.")


def peg_block(profile: Profile, out: Path, docs: Path, config_dir: str | None = None
              ) -> list[str]:
    """Sections 5 and 6 between ``PEG_BLOCK``'s markers (section 6 only where the profile has
    a Nextage budget or runs), each with its learners against DDPG and the random bar and its
    lines beside the thesis; writes their figures, episode CSVs and TensorBoard scalars."""
    out, docs = Path(out), Path(docs)
    data, figures = docs / "data" / profile.name, docs / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    lines = [PEG_BLOCK[0]]
    for experiment in PEG_EXPERIMENTS:
        budget = peg_budget_of(profile, experiment)
        results, randoms = peg_runs(profile, out, docs, experiment, config_dir)
        if experiment == "nextage" and budget is None and not results:
            continue
        episodes_csv(data / f"{experiment}_episodes.csv", results)
        episodes_csv(data / f"{peg.random_experiment(experiment)}_episodes.csv", randoms)
        export_runs(results, out / "tensorboard")
        specs = peg_specs_of(profile, experiment, config_dir)
        section, found = peg_section(results, figures, experiment, randoms,
                                     _provenance(profile.name, results, randoms,
                                                 (len(specs[0]), len(specs[1]))))
        lines += section
        if found:
            lines += [*peg_paired(found["pairs"], found["tail"]), ""]
            against = peg_against_random(results, randoms, found["tail"])
            lines += [*against, ""] if against else []
            notes = peg_thesis_notes(found, budget.lrs if budget is not None else ())
            lines += ["Beside the thesis (ch. 8.3.2):", "", *notes, ""] if notes else []
    return lines + [PEG_BLOCK[1]]
