"""Training scalars land in TensorBoard under Stable-Baselines3's tags, and in progress.csv."""
from __future__ import annotations

import csv

import pytest
from qg_learning_node.learner.training_log import EPISODE_WINDOW, TrainingLog


def test_scalars_are_readable_by_tensorboard_with_sb3_tags(tmp_path) -> None:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    log = TrainingLog(tmp_path)
    lengths = [50, 30, 10] + [5] * EPISODE_WINDOW
    step = 0
    for i, length in enumerate(lengths):
        step += length
        log.episode("train", length, success=length < 50, episode_return=-length / 10,
                    step=step, fps=12.5)
        log.training({"critic_loss": 0.5 / (i + 1), "actor_loss": 3.0, "mean_q": -20.0}, step)
    log.episode("test", 7, True, -0.7, step + 7, 12.5)
    log.evaluation([7, 200], [True, False], step + 207)
    log.close()

    events = EventAccumulator(str(tmp_path))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert {"rollout/ep_len_mean", "rollout/success_rate", "train/critic_loss",
            "train/actor_loss", "train/mean_q", "time/fps", "eval/mean_ep_length",
            "eval/success_rate"} <= tags
    ep_len = events.Scalars("rollout/ep_len_mean")
    assert ep_len[0].value == 50 and ep_len[1].value == 40 and ep_len[2].value == 30
    assert ep_len[-1].value == 5            # the window has forgotten the long early episodes
    ep_rew = events.Scalars("rollout/ep_rew_mean")          # a rolling mean too
    assert ep_rew[1].value == pytest.approx(-4.0) and ep_rew[-1].value == pytest.approx(-0.5)
    success = events.Scalars("rollout/success_rate")
    assert success[0].value == 0 and success[-1].value == 1
    assert events.Scalars("eval/success_rate")[0].value == pytest.approx(0.5)
    assert events.Scalars("eval/mean_ep_length")[0].step == step + 207

    with (tmp_path / "progress.csv").open() as f:
        rows = list(csv.DictReader(f))
    critic = [float(r["value"]) for r in rows if r["tag"] == "train/critic_loss"]
    assert len(critic) == len(lengths) and critic[0] == 0.5


def test_logging_scalars_loads_no_pytorch(tmp_path) -> None:
    """``qgl run``/``qgl demo`` log in their own process, which trains nothing: loading PyTorch
    there (1.1 s) delayed the stack it had just launched."""
    import subprocess
    import sys
    code = ("import sys\n"
            "from qg_learning_node.learner.training_log import TrainingLog\n"
            f"log = TrainingLog({str(tmp_path)!r})\n"
            "log.episode('train', 5, True, -0.5, 5, 10.0)\n"
            "log.close()\n"
            "print('torch' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stdout + out.stderr
    assert list(tmp_path.glob("events.out.tfevents.*"))
