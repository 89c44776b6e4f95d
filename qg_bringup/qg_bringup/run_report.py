"""What a finished run leaves beside its episodes: the learning curve against the random bar, a
video of the last test episode, and the one-line summary.
"""
from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

from qg_common.params import config_file

from qg_bringup.episode_schedule import EpisodeOutcome

__all__ = ["default_random_bar", "load_random_bar", "plot_learning_curve", "render_last_test",
           "summary_line"]


def default_random_bar() -> Path:
    """The simulation's random bar on the report seeds, as ``docs/results.md`` measured it:
    ``config/random_bar.json``, installed with the stack (a test keeps it equal to
    ``docs/data/thesis/random_bar.json``)."""
    return config_file("random_bar.json")


def load_random_bar(path: Path) -> dict | None:
    """``{label, mean, low, high, episodes, seeds}``, or None (with a note) if unreadable."""
    try:
        bar = json.loads(Path(path).read_text())
        return {k: bar[k] for k in ("label", "mean", "low", "high", "episodes", "seeds")}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"[qgl demo] no random bar drawn ({path}: {exc})", file=sys.stderr)
        return None


def plot_learning_curve(outcomes: list[EpisodeOutcome], path: Path, bar: dict | None,
          robot: str = "the simulated Panda") -> None:
    """Steps of every episode (training and test, inserted or not) against the random bar."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.8))
    for mode, colour in (("train", "tab:blue"), ("test", "tab:green")):
        runs = [o for o in outcomes if o.mode == mode]
        ax.plot([o.index for o in runs], [o.steps for o in runs], "-", color=colour, alpha=0.5)
        for success, marker in ((True, "o"), (False, "x")):
            sel = [o for o in runs if o.success == success]
            ax.plot([o.index for o in sel], [o.steps for o in sel], marker, color=colour,
                    label=f"{mode}, {'inserted' if success else 'not inserted'}")
    if bar is not None:
        ax.axhline(bar["mean"], color="grey", ls="--", lw=1,
                   label=f"random bar: {bar['label']}, {bar['mean']:.1f} steps (sim, "
                         f"{bar['episodes']} episodes on the report seeds)")
        ax.axhspan(bar["low"], bar["high"], color="grey", alpha=0.15, label="its 95 % interval")
    ax.set_xlabel("episode")
    ax.set_ylabel("steps to insert (cap = not inserted)")
    ax.set_title(f"QG-DDPG on {robot}, through the ROS stack")
    ax.grid(alpha=0.3)
    # Below the axes: inside, the legend would hide the first episodes and the bar.
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def render_last_test(outcomes: list[EpisodeOutcome], run_dir: Path) -> None:
    """The last test episode as a video beside the learning curve (``qgl render``); a demo
    without a renderer or that bag says why and goes on."""
    from qg_bringup.render import render_episode
    tests = [o for o in outcomes if o.mode == "test"]
    if not tests:
        return
    bag = run_dir / "episodes" / tests[-1].episode_id
    try:
        report = render_episode(bag, run_dir / "last_test_episode.mp4")
    except (RuntimeError, ValueError, OSError) as exc:
        print(f"[qgl demo] no video of the last test episode: {exc}", flush=True)
        return
    print(f"[qgl demo] the last test episode ({tests[-1].episode_id}, {tests[-1].steps} steps) "
          f"as a video: {report['out']} ({report['wall_s']:.1f} s to render)", flush=True)


def summary_line(outcomes: list[EpisodeOutcome], run_dir: Path, robots: Sequence[str],
             train_wall: float, learner_transitions: int, wall: float,
             codes: dict[str, int]) -> str:
    """The demo's last line: test result, training budget and time, where the outputs are."""
    tests = [o for o in outcomes if o.mode == "test"]
    train = [o for o in outcomes if o.mode == "train"]
    bags = sorted(p.parent.name for p in (run_dir / "episodes").glob("*/metadata.yaml"))
    per_robot = "" if robots == [""] else " (" + ", ".join(
        f"{r} {sum(b.startswith(r + '_') for b in bags)}" for r in robots) + ")"
    return (f"[qgl demo] test: {sum(o.success for o in tests)}/{len(tests)} inserted, mean steps "
            f"{sum(o.steps for o in tests) / max(1, len(tests)):.1f}; training: "
            f"{sum(o.steps for o in train)} RL steps, {sum(o.success for o in train)}/{len(train)} "
            f"inserted, on {len(robots)} robot(s) in {train_wall:.0f} s; the learner received "
            f"{learner_transitions} transitions; {len(bags)} MCAP "
            f"episodes{per_robot} in {run_dir / 'episodes'}; plot "
            f"{run_dir / 'learning_curve.png'}; TensorBoard {run_dir / 'tensorboard'}; "
            f"{wall:.0f} s; exit codes {codes}")
