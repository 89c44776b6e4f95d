"""``qgl up --recording NAME=VALUE`` and ``qgl run --recording``: the recorder's ``recording.*``
parameters on the robot process's command line, checked before anything starts, and kept in a
run's own stack file so that the same command continues the run recording alike."""
from __future__ import annotations

from pathlib import Path

import pytest
from qg_bringup.main import build_parser
from qg_bringup.stack_file import load_stack, stack_with_recording, with_recording
from qg_common.params import config_file


def test_qgl_up_puts_the_settings_on_the_robot_process_only() -> None:
    args = build_parser().parse_args(["up", "--recording", "mode=rl_rate",
                                      "--recording", "recording.budget_mb=500"])
    assert args.recording == [("recording.mode", "rl_rate"), ("recording.budget_mb", "500")]
    specs, _ = load_stack(config_file("stack.yaml"))
    changed = {s.name: s for s in with_recording(specs, args.recording)}
    assert changed["robot"].args[-5:] == ("--ros-args", "-p", "recording.mode:=rl_rate",
                                          "-p", "recording.budget_mb:=500")
    assert changed["robot"].command()[1:] == list(changed["robot"].args)
    before = {s.name: s for s in specs}
    assert all(changed[n] == before[n] for n in before if n != "robot")
    assert with_recording(specs, []) == specs


@pytest.mark.parametrize("value, message", [
    ("mode=sometimes", "recording.mode must be one of ['all', 'rl_rate', 'every_k']"),
    ("every_k=0", "recording.every_k must be >= 1"),
    ("budget=5", "NAME one of ['budget_mb', 'every_k', 'keep_last', 'min_free_mb', 'mode']"),
    ("budget_mb=lots", "could not convert string to float"),
    ("mode", "NAME=VALUE"),
])
def test_a_bad_setting_is_refused_with_the_reason(value: str, message: str,
                                                   capsys: pytest.CaptureFixture) -> None:
    for command in (["up"], ["run", "--episodes", "2"]):
        with pytest.raises(SystemExit) as exited:
            build_parser().parse_args([*command, "--recording", value])
        assert exited.value.code == 2
        assert message in capsys.readouterr().err


def test_a_runs_stack_file_keeps_the_settings_and_is_written_alike_again(tmp_path: Path) -> None:
    args = build_parser().parse_args(["run", "--episodes", "2", "--recording", "mode=every_k",
                                      "--recording", "keep_last=2"])
    out = stack_with_recording(config_file("stack.yaml"), args.recording, tmp_path / "s.yaml")
    text = out.read_text()
    specs, policy = load_stack(out)
    shipped, shipped_policy = load_stack(config_file("stack.yaml"))
    robot = next(s for s in specs if s.name == "robot")
    assert robot.args[-4:] == ("-p", "recording.mode:=every_k", "-p", "recording.keep_last:=2")
    assert policy == shipped_policy
    assert [s for s in specs if s.name != "robot"] == [s for s in shipped if s.name != "robot"]
    stack_with_recording(config_file("stack.yaml"), args.recording, out)
    assert out.read_text() == text       # the same command, the same plan: the run continues


@pytest.mark.ros
def test_an_episode_refused_at_a_full_disk_ends_aborted_with_the_reason(stack) -> None:
    """Robot and executor: the start is accepted, the reset refused (no disk has a billion MiB
    free), the episode ends ``aborted`` before its first step, and no bag is left."""
    from test_episodes import ROBOT, Episodes, executor_spec

    name, package, executable, args = ROBOT
    robot = (name, package, executable, (*args, "-p", "recording.min_free_mb:=1000000000.0"))
    stack.start(robot, executor_spec(max_steps=3, alone=True))
    with stack.client() as cli:
        episodes = Episodes(cli)
        episodes.wait_for_robot()
        reply = episodes.start(mode="train")
        assert reply.success, reply.message
        final = episodes.final(reply.episode_id, timeout=60.0)
    assert final.state == "aborted" and final.step == 0, (final.state, final.step)
    assert f"recording refused for {reply.episode_id}" in final.message, final.message
    assert "min_free_mb" in final.message
    episodes_dir = Path(stack.env["QG_RUNS_DIR"]) / "episodes"
    assert not episodes_dir.exists() or not any(episodes_dir.iterdir())
