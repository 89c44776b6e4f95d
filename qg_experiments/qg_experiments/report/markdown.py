"""The report's markdown: numbers as text, tables, and the grid's cells.

Every section of ``docs/results.md`` formats through these helpers, so a number, an interval or a
cell reads the same wherever it appears.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from qg_learning_node.learner.algorithms import label

from qg_experiments import stats
from qg_experiments.code_version import UNRECORDED
from qg_experiments.random_baselines import Bar

__all__ = ["fmt", "table", "APART_BLOCKS", "PEG_BLOCK", "marked_blocks", "write_marked_block",
           "speed", "bar_text", "grid_cell", "grid_table", "code_label"]


def fmt(x: float | None, digits: int = 1) -> str:
    """``x`` with ``digits`` decimals; ``n/a`` for a missing or NaN value. From a million on,
    in powers of ten (``7.87e+07``): a diverged critic's error reads as its size, not as a row
    of digits."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    return f"{x:.2e}" if abs(x) >= 1e6 else f"{x:.{digits}f}"


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A markdown table, one line per row."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + \
        ["| " + " | ".join(r) + " |" for r in rows]


#: What runs saved before a run recorded its step ran on: pybullet, 0.25 s step limit.
OLD_STEP = ("pybullet", 0.25)


def step_label(results: list[dict[str, Any]]) -> str:
    """The physics engine and RL step limit ``results`` ran on, as a phrase: ``pybullet, step
    limit 0.25 s`` (several where they mix). Runs saved before a run recorded them are the old
    step's (``OLD_STEP``), so their sections stay readable and say which MDP they measured."""
    steps = sorted({(str(r.get("engine", OLD_STEP[0])), float(r.get("step_limit", OLD_STEP[1])))
                    for r in results})
    return "; ".join(f"{engine}, step limit {limit:g} s" for engine, limit in steps)


def code_label(results: list[dict[str, Any]]) -> str:
    """The commits ``results`` were made at (``code_version``), most runs first, with how many
    runs each and whether its checkout had modified files; runs that recorded none last. A run
    continued from saved progress (``run_progress``: its ``resumed`` entries) counts under each
    commit it ran on."""
    counts: dict[tuple[str, bool], int] = {}
    unrecorded = resumed = 0
    for r in results:
        code = r.get("code", UNRECORDED)
        if code["commit"] is None:
            unrecorded += 1
            continue
        resumed += bool(r.get("resumed"))
        for key in {(c["commit"][:10], bool(c["modified"]))
                    for c in (code, *(part["code"] for part in r.get("resumed", ())))
                    if c["commit"] is not None}:
            counts[key] = counts.get(key, 0) + 1
    parts = [f"`{commit}`{' with modified files' if modified else ''} ({n} runs)"
             for (commit, modified), n in sorted(counts.items(), key=lambda kv: -kv[1])]
    if resumed:
        parts.append(f"{resumed} of them continued from saved progress, counted under each "
                     "commit they ran on")
    if unrecorded:
        parts.append(f"not recorded ({unrecorded} runs, saved before runs recorded it)")
    return "; ".join(parts)


def speed(results: list[dict[str, Any]]) -> str:
    """The step's engine and limit, RL steps, worker time and simulated time of ``results``,
    as one phrase. The worker time is the runs' CPU time when every run recorded it
    (``run_worker.run_one``): a sweep paused or sharing its cores counts its wall time, not its
    work. Runs read back from their episode rows (``episode_rows``) kept no timing: the phrase
    is over the others, and says how many they are."""
    timed = [r for r in results if "wall_time" in r]
    if not timed:
        return "not kept (every run read back from its episode rows)"
    if len(timed) < len(results):
        return f"over the {len(timed)} runs that kept their timing, {speed(timed)}"
    steps = sum(r.get("rl_steps", 0) for r in results)
    wall = sum(r["wall_time"] for r in results)
    sim = sum(r.get("sim_time", 0.0) for r in results)
    timeouts = sum(r.get("step_timeouts", 0) for r in results)
    cpu = [r.get("cpu_time") for r in results]
    if cpu and None not in cpu:
        work = sum(cpu)
        text = (f"{steps} RL steps in {work / 60:.1f} worker-minutes of CPU "
                f"({steps / work:.2f} steps/s; {wall / 60:.1f} of wall time)")
    else:
        text = f"{steps} RL steps in {wall / 60:.1f} worker-minutes ({steps / wall:.2f} steps/s)"
    if sim:                    # a robot's loop, whose steps end at rest or at the step limit
        text = f"{step_label(results)}; {text}"
        text += (f", {sim / max(steps, 1) * 1e3:.0f} ms simulated per step, "
                 f"{timeouts / max(steps, 1):.0%} of steps ended by the step timeout, not at rest")
    return text


def bar_text(bar: Bar | None) -> str:
    """What the random bar is, in words."""
    if bar is None:
        return "no random baseline run: nothing marked"
    return (f"{bar.label}, {stats.format_interval(bar.interval)} steps over "
            f"{bar.interval.n} episodes cut at the test cap of {bar.cap}")


def grid_cell(row: dict[str, Any] | None) -> str:
    """``**12.3** [8.1, 17.0] (39/40)``: bold when the whole interval is below the bar."""
    if row is None:
        return "—"
    mark = "**" if row["beats_random"] else ""
    inserted = row["test_episodes"] - row["test_failures"]
    return (f"{mark}{fmt(row['mean_test_steps'])}{mark} [{fmt(row['ci_low'])}, "
            f"{fmt(row['ci_high'])}] ({inserted}/{row['test_episodes']})")


def grid_table(rows: list[dict[str, Any]], caption: str) -> list[str]:
    """The cells of ``rows`` (``grid.cell_table``), one line per cell, an algorithm per column."""
    cells = sorted({(r["critic_lr"], r["iterations"]) for r in rows})
    algorithms = sorted({r["algorithm"] for r in rows})
    by_key = {(r["algorithm"], r["critic_lr"], r["iterations"]): r for r in rows}
    return [caption, ""] + table(
        ["critic lr", "iterations/cycle", *[label(a) for a in algorithms]],
        [[f"{lr:g}", str(it), *[grid_cell(by_key.get((a, lr, it))) for a in algorithms]]
         for lr, it in cells])


#: The sections of results.md that their own commands write apart from the page, as (begin,
#: end) markers: the peers' and the standard tasks' (``peers_report``), the Franka's
#: (``franka_report``). A page written anew keeps them (``marked_blocks``).
PEERS_BLOCK = ("<!-- peers: written by qg_experiments.peers_report -->", "<!-- /peers -->")
STANDARD_BLOCK = ("<!-- standard tasks: written by qg_experiments.peers_report -->",
                  "<!-- /standard tasks -->")
FRANKA_BLOCK = ("<!-- franka section: python -m qg_experiments.franka_report -->",
                "<!-- end of the franka section -->")
#: The peg's sections (``report.peg_block``): written with the page, and alone by
#: ``python -m qg_experiments.peg_report`` while a sweep's runs come in.
PEG_BLOCK = ("<!-- peg sections: also written alone by python -m qg_experiments.peg_report -->",
             "<!-- end of the peg sections -->")
APART_BLOCKS = [PEERS_BLOCK, STANDARD_BLOCK, FRANKA_BLOCK]


def _block_span(text: str, begin: str, end: str) -> tuple[int, int] | None:
    """Where the block from ``begin`` to the first ``end`` after it lies in ``text`` (markers
    included), or ``None`` when the page has no such block."""
    start = text.find(begin)
    stop = text.find(end, start + len(begin)) if start >= 0 else -1
    return None if stop < 0 else (start, stop + len(end))


def marked_blocks(text: str, markers: list[tuple[str, str]]) -> str:
    """The blocks of ``text`` that lie between each (begin, end) pair of ``markers``, markers
    included, in the order the page has them: what a page written anew must carry over, since
    the sections made apart from it (the peers', the Franka's) have their runs elsewhere."""
    spans = sorted(span for begin, end in markers
                   if (span := _block_span(text, begin, end)) is not None)
    return "\n\n".join(text[start:stop] for start, stop in spans)


def write_marked_block(page: Path, begin: str, end: str, block: str) -> None:
    """Put ``block`` (which starts with ``begin`` and ends with ``end``) into ``page`` in place
    of the block between those markers, or append it: a section made apart from the rest of
    the page (the peers', the Franka's) survives the page being written anew around it."""
    text = page.read_text() if page.exists() else ""
    span = _block_span(text, begin, end)
    if span is not None:
        text = text[:span[0]] + block.rstrip("\n") + text[span[1]:]
    else:
        text = text.rstrip("\n") + "\n\n" + block
    page.write_text(text)
