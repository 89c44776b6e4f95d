"""Stall recovery at deployment: notice the test actor's fixed point and shake it loose.

Why: without exploration noise the trained actor can hold the shaft at its own fixed point
(docs/learning.md section 15): the arm comes to rest at the same state step after step and the
actor repeats the same action until the step cap, while the same actor with the training noise
inserts. :class:`StallRecovery` watches an episode's (state, action) pairs, one per RL step,
each step ending with the arm at rest. When over ``window`` steps both repeat themselves within
a tolerance, with a period of one step (a fixed point) or a few (a limit cycle: the action tips
the shaft one way and back), it perturbs the next ``steps`` actions with seeded noise (the
training noise of ``noise.py``, or a dither) and counts one recovery.

Where the state measures the step's progress itself (the ``tilt_motion`` state's motion along
the bore, ``residual_task.PROGRESS_COMPONENTS``), no progress is read from the state directly:
over the window no step moved more than ``progress_tolerance`` and no other component (the
tilt) spread over more than that. A repeat test cannot work there: at a jam the motion reads 0
plus the measured pose's noise, a jitter of up to 0.03 in state units, 30 times the repeat
tolerance, and the actor's action follows it. The tilt's spread tells a jam from a shaft the
actor is still turning upright before it slides (learning.md section 21).

Off by default: the thesis protocol tests the deterministic actor, and its numbers never
include a recovery (the runner runs recovered test episodes apart, mode ``recovery``). Pure
(no rclpy): the executor node and the in-process runner share it.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from qg_learning_node.executor.noise import ActionNoise, NoiseConfig

__all__ = ["StallRecoveryConfig", "StallRecovery", "PERTURBATIONS", "stalled", "first_stall"]

#: ``noise``: the executor's training noise (section ``noise``) on the actor's action;
#: ``dither``: +-``dither`` per dimension, the signs drawn at random.
PERTURBATIONS = ("noise", "dither")


@dataclass(frozen=True)
class StallRecoveryConfig:
    """When an episode counts as stalled and what is done about it (``stall_recovery``).

    :param enabled: recover in test episodes (training has its noise already); off by default,
        the thesis protocol.
    :param window: [steps] the stretch over which no progress means a stall.
    :param max_period: [steps] the longest cycle that counts as no progress: 1 = only a fixed
        point; 2 also the two-step cycles measured on the tuning seeds.
    :param state_tolerance: [state units, the actor's input] a stall's largest change of any
        state dimension against the same phase of its cycle, over the window. Measured: fixed
        points <= 1.4e-4, two-step cycles <= 3e-4.
    :param action_tolerance: [actor-output units, 1 = full residual] the same for the actor's
        own (unperturbed) action. Measured: fixed points <= 3.7e-4, two-step cycles <= 2.2e-3.
    :param progress_tolerance: [state units] in a state with progress components (the step's
        motion), the most a step may move, and the most any other component may spread over the
        window, and still be no progress; 0.05 is 0.1 mm at ``task.motion_range`` 2 mm (a step
        that slides moves 1-5 mm). Measured at jams: motion <= 0.031, tilt spread <= 0.033; a
        tilt being turned upright spreads 0.16-1.6. Replaces both tolerances above there.
    :param steps: [steps] perturbed actions of an episode's first recovery.
    :param growth: each further recovery of the episode perturbs this many times as many steps
        as the one before (1 = always ``steps``): a jam that ``steps`` noisy actions did not
        free gets longer ones, as training's every-step noise did (learning.md section 21).
    :param perturbation: ``noise`` | ``dither`` (:data:`PERTURBATIONS`).
    :param dither: [actor-output units] the dither's amplitude (``dither`` only).
    :param max_recoveries: recoveries per episode at most; 0 = no limit.
    """
    enabled: bool = False
    window: int = 10
    max_period: int = 2
    state_tolerance: float = 1e-3
    action_tolerance: float = 3e-3
    progress_tolerance: float = 0.05
    steps: int = 5
    growth: float = 2.0
    perturbation: str = "noise"
    dither: float = 0.3
    max_recoveries: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ValueError(f"stall_recovery.enabled must be true or false, got "
                             f"{self.enabled!r}")
        for name in ("window", "steps", "max_period"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"stall_recovery.{name} must be an integer >= 1 [steps], "
                                 f"got {value!r}")
        if self.window <= self.max_period:
            raise ValueError(f"stall_recovery.window ({self.window}) must be longer than "
                             f"max_period ({self.max_period}): a repeat needs both ends in "
                             "the window")
        for name in ("state_tolerance", "action_tolerance", "progress_tolerance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0.0:
                raise ValueError(f"stall_recovery.{name} must be finite and >= 0, got {value!r}")
        if not (np.isfinite(self.growth) and self.growth >= 1.0):
            raise ValueError(f"stall_recovery.growth must be a finite factor >= 1, got "
                             f"{self.growth!r}")
        if self.perturbation not in PERTURBATIONS:
            raise ValueError(f"stall_recovery.perturbation must be one of {PERTURBATIONS}, "
                             f"got {self.perturbation!r}")
        if not 0.0 < self.dither <= 2.0:
            raise ValueError(f"stall_recovery.dither must be in (0, 2] actor-output units, "
                             f"got {self.dither!r}")
        if (isinstance(self.max_recoveries, bool) or not isinstance(self.max_recoveries, int)
                or self.max_recoveries < 0):
            raise ValueError(f"stall_recovery.max_recoveries must be an integer >= 0 "
                             f"(0 = no limit), got {self.max_recoveries!r}")

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> StallRecoveryConfig:
        """From the ``stall_recovery`` section; an unknown key is refused with its name."""
        unknown = sorted(set(values) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"stall_recovery: unknown parameters {unknown}; known: "
                             f"{sorted(cls.__dataclass_fields__)}")
        return cls(**values)


def stalled(states: np.ndarray, actions: np.ndarray, config: StallRecoveryConfig,
            progress: Sequence[int] = ()) -> bool:
    """Whether the last ``config.window`` (state, action) pairs show no progress.

    With progress components (the state's indices ``progress``): every one of them stayed
    within ``config.progress_tolerance`` of 0 at every step, and every other state component
    within a band that wide. Without: for some period ``p`` up to ``config.max_period``, every
    state and action there differs from the one ``p`` steps before it by at most its tolerance
    (every dimension)."""
    states = np.asarray(states, dtype=np.float64)
    actions = np.asarray(actions, dtype=np.float64)
    if len(states) != len(actions):
        raise ValueError(f"{len(states)} states but {len(actions)} actions")
    if len(states) < config.window:
        return False
    s, a = states[-config.window:], actions[-config.window:]
    if progress:
        rest = np.delete(s, list(progress), axis=1)
        spread = (rest.max(axis=0) - rest.min(axis=0)).max(initial=0.0)
        return bool(max(np.abs(s[:, list(progress)]).max(), spread)
                    <= config.progress_tolerance)
    for p in range(1, config.max_period + 1):
        if (np.abs(s[p:] - s[:-p]).max(initial=0.0) <= config.state_tolerance
                and np.abs(a[p:] - a[:-p]).max(initial=0.0) <= config.action_tolerance):
            return True
    return False


def first_stall(states: np.ndarray, actions: np.ndarray, config: StallRecoveryConfig,
                progress: Sequence[int] = ()) -> int | None:
    """The first step index at which a recorded episode (state ``t`` and the action chosen on
    it, one row per step) is stalled by :func:`stalled`; ``None`` if it never is."""
    for end in range(config.window, len(states) + 1):
        if stalled(states[end - config.window:end], actions[end - config.window:end], config,
                   progress):
            return end - 1
    return None


class StallRecovery:
    """One episode's stall watch: :meth:`act` between the actor and the robot.

    :param action_dim: the action's length.
    :param seed: the perturbation's seed (one stream per episode: the same seed, the same
        perturbations).
    :param noise: the training noise (``perturbation: noise``); the executor's ``noise``
        section.
    :param progress: the state's progress components (``ResidualTask.progress_dims``).
    """

    def __init__(self, config: StallRecoveryConfig, action_dim: int, seed: int,
                 noise: NoiseConfig | None = None, progress: Sequence[int] = ()) -> None:
        self.config = config
        self.progress = tuple(progress)
        self.action_dim = action_dim
        self.noise = ActionNoise(noise or NoiseConfig(), action_dim, seed)
        self.rng = np.random.default_rng(seed)
        self.step = 0
        #: How many recoveries began, and at which steps.
        self.recoveries = 0
        self.started_at: list[int] = []
        self._remaining = 0
        #: Whether the last action :meth:`act` returned was perturbed.
        self.perturbed = False
        self._states: list[np.ndarray] = []
        self._actions: list[np.ndarray] = []

    def act(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The action to send for the actor's ``action`` on ``state``: the same action, or,
        while recovering, a perturbed one in [-1, 1]. A stall starts a recovery here."""
        step, self.step = self.step, self.step + 1
        action = np.asarray(action, dtype=np.float64)
        self.perturbed = self._remaining > 0
        if self.perturbed:
            self._remaining -= 1
            return self._perturb(action)
        self._states.append(np.asarray(state, dtype=np.float64).copy())
        self._actions.append(action.copy())
        del self._states[:-self.config.window], self._actions[:-self.config.window]
        limit = self.config.max_recoveries
        if (not stalled(np.array(self._states), np.array(self._actions), self.config,
                        self.progress)
                or (limit and self.recoveries >= limit)):
            return action
        self.recoveries += 1
        self.started_at.append(step)
        self._states.clear()             # after it, a stall needs a whole window again
        self._actions.clear()
        self._remaining = self.recovery_steps(self.recoveries) - 1
        self.perturbed = True
        return self._perturb(action)

    def recovery_steps(self, number: int) -> int:
        """How many actions recovery ``number`` (1 = the episode's first) perturbs."""
        return max(1, round(self.config.steps * self.config.growth ** (number - 1)))

    def _perturb(self, action: np.ndarray) -> np.ndarray:
        if self.config.perturbation == "noise":
            return self.noise.perturb(action)
        signs = self.rng.choice((-1.0, 1.0), self.action_dim)
        return np.clip(action + self.config.dither * signs, -1.0, 1.0)
