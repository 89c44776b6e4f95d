"""The Gymnasium environments: registered, valid by gymnasium's own checker, reproducible per
seed, the runner's task step for step, and trainable by Stable-Baselines3 as a user would."""
from __future__ import annotations

import gymnasium
import numpy as np
import pytest
import qg_experiments.gym_envs as gym_envs
from gymnasium.utils.env_checker import check_env
from qg_experiments.gym_envs.insertion import InsertionEnv
from qg_experiments.runner import InsertionRobot, StackSettings, run_episode
from qg_learning_node.executor.episode import Episode

#: A fixed action sequence (actor units) for the step-by-step comparisons.
ACTIONS = np.array([[0.8, -0.3], [-0.5, 0.9], [0.1, 0.1], [-1.0, 0.4]])


def _rollout(env: gymnasium.Env, seed: int, actions: np.ndarray, **options):
    obs, info = env.reset(seed=seed, options=options or None)
    out = [(obs.copy(), 0.0, False, False, info["position_error"])]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        out.append((obs.copy(), reward, terminated, truncated, info["position_error"]))
        if terminated or truncated:
            break
    return out


class _no_warnings:
    """``check_env`` reports soft problems as warnings: none may come."""

    def __enter__(self):
        import warnings
        self._catch = warnings.catch_warnings(record=True)
        self.caught = self._catch.__enter__()
        warnings.simplefilter("always")
        return self

    def __exit__(self, *exc):
        self._catch.__exit__(*exc)
        assert [str(w.message) for w in self.caught] == []


def test_every_environment_is_registered_and_named_by_module() -> None:
    for env_id in gym_envs.ENV_IDS:
        assert env_id in gymnasium.registry
    env = gymnasium.make("qg_experiments:QGInsertion-v0", max_steps=2)
    assert env.unwrapped.max_steps == 2 and env.spec.max_episode_steps is None
    env.close()


@pytest.mark.parametrize("env_id", sorted(gym_envs.IN_PROCESS_ENV_IDS))
@pytest.mark.slow
def test_in_process_environments_pass_gymnasiums_checker(env_id: str) -> None:
    env = gymnasium.make(env_id).unwrapped
    with _no_warnings():
        check_env(env, skip_render_check=True)
    env.close()


@pytest.mark.slow
def test_a_seeded_insertion_episode_is_identical_twice() -> None:
    env = InsertionEnv(max_steps=3)
    first = _rollout(env, 7, ACTIONS)
    _rollout(env, 8, ACTIONS[::-1])          # another robot in between
    second = _rollout(env, 7, ACTIONS)
    env.close()
    assert len(first) == 4 and first[-1][3]               # the cap of 3 truncates, not terminal
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:] == b[1:]
    assert not np.array_equal(first[1][0], _rollout(InsertionEnv(max_steps=3), 8, ACTIONS)[1][0])


def test_a_seeded_peg_episode_is_identical_twice() -> None:
    env = gymnasium.make("QGNextagePeg-v0", max_steps=3).unwrapped
    actions = np.c_[ACTIONS, -ACTIONS[:, :1]]           # the peg's actions are 3-D
    first, second = _rollout(env, 5, actions), _rollout(env, 5, actions)
    env.close()
    assert len(first) == 4 and first[-1][3] and not first[-1][2]
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:] == b[1:]


def test_the_environment_is_the_runners_task_step_for_step() -> None:
    """Same arm seed, same start pose, same actions: the runner's ``run_episode`` and the
    environment see the same states and rewards (float32 states aside)."""
    settings = StackSettings.load().with_arm_seed(3)
    task = InsertionRobot(settings)
    actions = iter(ACTIONS)
    records = []
    episode = Episode("e", "train", 2, "dense", task.residual)
    episode.max_steps = len(ACTIONS)
    run_episode(task, episode, lambda state: next(actions), records.append)
    task.close()
    env = InsertionEnv(max_steps=len(ACTIONS))
    env.reset(seed=3)
    rollout = _rollout(env, 3, ACTIONS, pose=2)
    env.close()
    assert len(records) == len(ACTIONS) == len(rollout) - 1
    for record, step in zip(records, rollout[1:]):
        np.testing.assert_array_equal(record.next_state.astype(np.float32), step[0])
        assert record.reward == step[1]


def test_reset_options_pick_the_pose_and_the_cap() -> None:
    env = InsertionEnv(max_steps=50)
    env.reset(seed=0)
    assert env.episode.initial_pose == 0
    env.reset()
    assert env.episode.initial_pose == 1                 # the poses rotate
    _, info = env.reset(options={"pose": 6, "max_steps": 1})
    assert info["pose"] == 6 and env.episode.max_steps == 1
    *_, truncated, info = env.step(np.zeros(2))
    assert truncated and info["end_reason"] == "step_cap"
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="pose"):
        env.reset(options={"pose": 8})
    with pytest.raises(ValueError, match="unknown"):
        env.reset(options={"start": 1})
    env.close()
    with pytest.raises(ValueError, match="arm"):
        InsertionEnv(arm="perfect")


def test_the_ideal_arm_and_the_arm_seed_are_options() -> None:
    def start(**kwargs) -> np.ndarray:
        env = InsertionEnv(**kwargs)
        obs, _ = env.reset(seed=11)
        env.close()
        return obs
    ideal = start(arm="ideal")
    np.testing.assert_array_equal(ideal, start(arm="ideal", arm_seed=4))  # no imperfection
    assert not np.array_equal(start(), start(arm_seed=4))                  # another robot
    assert not np.array_equal(start(), ideal)


@pytest.mark.slow
def test_stable_baselines3_trains_on_the_environment_in_three_lines(monkeypatch, tmp_path) -> None:
    from stable_baselines3 import SAC
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path))   # SB3's empty log folder, else in /tmp
    env = gymnasium.make("qg_experiments:QGInsertion-v0", max_steps=3)
    model = SAC("MlpPolicy", env, learning_starts=2, batch_size=4, seed=0, device="cpu")
    model.learn(total_timesteps=6)
    assert model.num_timesteps == 6 and model._n_updates >= 4
    action, _ = model.predict(env.observation_space.sample(), deterministic=True)
    assert env.action_space.contains(action)
    env.close()


@pytest.mark.slow
def test_record_video_writes_a_playable_video_of_qginsertion(tmp_path) -> None:
    """``render_mode="rgb_array"``: gymnasium's own ``RecordVideo`` records an episode
    unchanged, one frame at the reset and one per step, and the arm moves between them."""
    import imageio_ffmpeg
    from gymnasium.wrappers import RecordVideo
    env = RecordVideo(gymnasium.make("qg_experiments:QGInsertion-v0", render_mode="rgb_array",
                                     max_steps=len(ACTIONS)),
                      str(tmp_path), episode_trigger=lambda episode: True, disable_logger=True)
    env.reset(seed=0)
    for steps, action in enumerate(ACTIONS, start=1):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    env.close()
    (video,) = tmp_path.glob("*.mp4")
    reader = imageio_ffmpeg.read_frames(str(video))
    width, height = next(reader)["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(height, width, 3) for f in reader]
    assert (width, height) == (448, 336) and len(frames) == steps + 1
    assert np.abs(frames[0].astype(int) - frames[-1]).max(axis=2).mean() > 0.5


@pytest.mark.parametrize("env_id", sorted(set(gym_envs.IN_PROCESS_ENV_IDS)
                                           - {"QGSparseMountainCar-v0",    # Gymnasium's car
                                              "QGPeg-v0"}))                # no arm to draw
def test_in_process_environments_render_rgb_arrays_and_refuse_other_modes(
        env_id: str, monkeypatch: pytest.MonkeyPatch) -> None:
    assert gymnasium.spec(env_id).entry_point
    env = gymnasium.make(env_id, render_mode="rgb_array")
    assert env.metadata["render_modes"] == ["rgb_array", "human"]
    env.reset(seed=1)
    frame = env.render()
    assert frame.shape == (336, 448, 3) and frame.dtype == np.uint8 and frame.std() > 10
    env.close()
    with pytest.raises(ValueError, match="render_mode"):
        gymnasium.make(env_id, render_mode="ansi")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(ValueError, match="needs a display"):
        gymnasium.make(env_id, render_mode="human")


def test_the_sparse_mountain_car_pays_minus_one_per_step_and_zero_at_the_goal() -> None:
    env = gymnasium.make("qg_experiments:QGSparseMountainCar-v0")
    obs, _ = env.reset(seed=0)
    rewards = []
    while True:           # push with the velocity: the swing reaches the goal
        obs, reward, terminated, truncated, info = env.step(
            np.array([1.0 if obs[1] >= 0 else -1.0], np.float32))
        rewards.append(reward)
        if terminated or truncated:
            break
    assert terminated and info["is_success"] and rewards[-1] == 0.0
    assert rewards[:-1] == [-1.0] * (len(rewards) - 1) and 50 < len(rewards) < 300
    env.close()


def test_the_free_peg_is_the_experiments_environment_and_refuses_a_nan() -> None:
    """``QGPeg-v0``'s episode from start k is the one experiment 5's episode k runs: the same
    states and rewards for the same actions; a cap truncates; a NaN action is refused."""
    from qg_common.params import config_file, load_ros_params
    from qg_experiments.environments import make_environment

    env = gymnasium.make("qg_experiments:QGPeg-v0", max_steps=3).unwrapped
    own = make_environment("peg", load_ros_params(config_file("peg_env.yaml")), episode_steps=3)
    obs, info = env.reset(seed=0, options={"start": 11})
    assert info["start"] == 11 and not info["is_success"]
    np.testing.assert_array_equal(obs, own.reset(seed=11).astype(np.float32))
    actions = [np.array([0.5, -1.0, 0.2]), np.zeros(3), np.array([-1.0, 1.0, -1.0])]
    for k, action in enumerate(actions):
        obs, reward, terminated, truncated, info = env.step(action.astype(np.float32))
        state, own_reward, own_terminal = own.step(action.astype(np.float32).astype(float))
        np.testing.assert_array_equal(obs, state.astype(np.float32))
        assert reward == own_reward < 0.0 and terminated == own_terminal is False
        assert truncated == (k == 2) and info["position_error"] > 0.0075
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(np.zeros(3))
    env.reset(seed=1)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0, 0.0]))
    env.close()
    own.close()
