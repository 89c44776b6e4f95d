"""Child of the across-machines test: the operator, on the learner's machine (network namespace).

Waits for the learner and, over the link, for the robot; runs one training episode on the other
machine by service call, waits until the learner has every transition of it, and prints one JSON
line: the episode id, its steps, and the learner's transitions, actor version and updates.
A failed wait raises (exit code 1, the reason on stderr).
Usage: python netns_operator.py DOMAIN_ID
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path[:0] = [str(Path(__file__).parent), str(Path(__file__).parents[1])]

from qg_common.ros_client import CliNode  # noqa: E402
from test_episodes import Episodes  # noqa: E402


def main() -> None:
    with CliNode("operator", domain_id=int(sys.argv[1])) as cli:
        episodes = Episodes(cli)
        episodes.wait_for_learner(timeout=60.0)
        episodes.wait_for_robot(timeout=120.0)
        response = episodes.start(mode="train", initial_pose=1, seed=3)
        assert response.success, response.message
        final = episodes.final(response.episode_id, timeout=240.0)
        assert final.state == "done", final.message
        cli.spin_until(lambda: episodes.learner_heartbeats[-1].transitions >= final.step, 30.0)
        learner = episodes.learner_heartbeats[-1]
        print(json.dumps({"episode_id": response.episode_id, "steps": int(final.step),
                          "transitions": int(learner.transitions),
                          "actor_version": int(learner.actor_version),
                          "executor_actor_version": int(final.actor_version)}), flush=True)


if __name__ == "__main__":
    main()
