"""The trained policy as one file a robot runs: the actor's weights and the spec it needs.

A learner checkpoint (``learner.pt``) holds everything to continue training, and only the learner
can load it (torch, replay memory, Q-Graph). A policy file holds what running the actor needs:

- the actor's layers (float32 weight and bias, the bits the executor ran in training);
- its spec: task kind, observation kind, state and action sizes, the hidden activation, the
  robot it was trained on, the task settings the state and action are scaled by (the
  observation's ranges, the action's torque or offset scale, the base push), the format version
  and where it came from (source run or checkpoint, RL steps, train steps, actor version).

Format: a NumPy ``.npz`` archive (a zip of ``.npy`` arrays) with the spec as JSON in the array
``header`` and the layers as ``layer<k>.weight`` / ``layer<k>.bias``. Why this format: a robot's
computer runs it with numpy alone (the executor never imports torch, ``learner/actor_mlp.py``);
it is read with ``allow_pickle=False``, so loading a file runs no code (``torch.load`` of a
checkpoint unpickles); the weights keep their exact float32 bits, so a frozen actor gives the
actions the trained one gave; any language with a zip and an ``.npy`` reader can read it.

The executor (``policy.file``) refuses a file whose task, observation, sizes, settings or robot
do not match its own stack, at start-up, with the reasons (:func:`mismatches`). Pure: no rclpy,
no torch.
"""
from __future__ import annotations

import hashlib
import json
import math
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FORMAT", "FORMAT_VERSION", "SUFFIX", "ROBOT_FAMILIES", "ACTIVATIONS",
           "PolicyFileError", "PolicySpec", "Policy", "task_settings", "spec_for_task",
           "robot_family", "mismatches", "check_compatible", "save_policy", "load_policy",
           "frozen_policy"]

#: What the header's ``format`` says (a file of something else is refused by name).
FORMAT = "qg-policy"
#: Raised when the layout changes; a reader refuses a newer version than its own.
FORMAT_VERSION = 1
SUFFIX = ".npz"

#: Robots (plugin names, ``robot:=...``) that run the same task on the same kind of arm: an
#: actor trained on one runs on the others (the residual is a wrench in the tool frame, the
#: state the tool's tilt and the contact wrench). The Panda in MuJoCo or pybullet and the FR3
#: through libfranka (franky-sim or a real arm) are one family: the sim-to-real transfer.
#: A robot not listed is its own family.
ROBOT_FAMILIES = {
    "sim_panda": "franka", "sim_panda_mujoco": "franka", "sim_panda_pybullet": "franka",
    "franka": "franka", "sim_xarm7": "xarm7", "sim_nextage": "nextage",
}

#: The actor's hidden activations (its output is always tanh, actions in [-1, 1]).
ACTIVATIONS = {"tanh": np.tanh, "relu": lambda x: np.maximum(x, np.float32(0.0))}

#: The residual task's scale of each state component (``executor/residual_task.py``).
_COMPONENT_SCALE = {"fx": "force_range", "fy": "force_range", "tx": "torque_range",
                    "ty": "torque_range", "ex": "tilt_range", "ey": "tilt_range",
                    "depth": "depth_range", "motion": "motion_range"}


class PolicyFileError(ValueError):
    """A policy file is unreadable, malformed, or does not fit the stack (the reasons)."""


def robot_family(robot: str) -> str:
    """The family of the robot plugin ``robot`` (:data:`ROBOT_FAMILIES`; else itself)."""
    return ROBOT_FAMILIES.get(robot, robot)


@dataclass(frozen=True)
class PolicySpec:
    """What an actor needs from the stack that runs it.

    :param task: the task kind (``residual``: the shaft's residual force policy; ``peg``).
    :param observation: the state definition (``tilt_only``, ``tilt``, ..., or ``peg``).
    :param state_dim: length of the scaled state; :param action_dim: of the action.
    :param robot: the robot plugin it was trained on (``sim_panda``); :data:`ROBOT_FAMILIES`
        says where else it runs.
    :param settings: the task settings the state and action are scaled by (:func:`task_settings`).
    :param hidden_activation: the actor's hidden activation (:data:`ACTIVATIONS`).
    :param provenance: where it came from: ``source``, ``steps``, ``updates``, ``actor_version``,
        the algorithm and seed, when it was exported.
    """
    task: str
    observation: str
    state_dim: int
    action_dim: int
    robot: str
    settings: dict[str, Any]
    hidden_activation: str = "tanh"
    provenance: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.state_dim < 1 or self.action_dim < 1:
            raise PolicyFileError(f"state and action sizes must be >= 1, got {self.state_dim}, "
                                  f"{self.action_dim}")
        if self.hidden_activation not in ACTIVATIONS:
            raise PolicyFileError(f"hidden_activation must be one of {sorted(ACTIVATIONS)}, "
                                  f"got {self.hidden_activation!r}")
        if not self.task or not self.observation or not self.robot:
            raise PolicyFileError("task, observation and robot must be named")

    def describe(self) -> str:
        """One line: what it runs on."""
        return (f"{self.task} task, observation {self.observation} ({self.state_dim}-D states, "
                f"{self.action_dim}-D actions), trained on {self.robot}")


def task_settings(task: Any) -> dict[str, Any]:
    """The settings of the executor's ``task`` that its state and action are scaled by.

    Residual (``ResidualTask``): the base push, the torque of a unit action and the range of
    each state component the observation uses. Peg (``PegTask``): the offset of a unit action
    and the workspace the tip is scaled from. These are the numbers that, changed, make the
    same weights mean another policy.
    """
    config = task.config
    if hasattr(config, "observation"):          # the residual force policy
        from qg_learning_node.executor.residual_task import OBSERVATION_COMPONENTS
        names = ["base_force", "max_residual_torque",
                 *sorted({_COMPONENT_SCALE[c] for c in OBSERVATION_COMPONENTS[config.observation]})]
        return {name: float(getattr(config, name)) for name in names}
    geometry = task.cell.geometry                # the peg: offsets in a workspace
    return {"action_scale": float(config.action_scale),
            "workspace_low": [float(x) for x in geometry.workspace_low],
            "workspace_high": [float(x) for x in geometry.workspace_high]}


def spec_for_task(task_kind: str, task: Any, robot: str, hidden_activation: str = "tanh",
                  provenance: dict[str, Any] | None = None) -> PolicySpec:
    """The spec of an actor for the executor's ``task`` (of kind ``task_kind``) on ``robot``."""
    observation = getattr(task.config, "observation", task_kind)
    return PolicySpec(task=task_kind, observation=observation, state_dim=int(task.state_dim),
                      action_dim=int(task.action_dim), robot=robot,
                      settings=task_settings(task), hidden_activation=hidden_activation,
                      provenance=dict(provenance or {}))


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return a == b


def mismatches(spec: PolicySpec, stack: PolicySpec) -> list[str]:
    """Every way the file's ``spec`` does not fit the ``stack`` (the executor's own spec, from
    :func:`spec_for_task`); empty when it runs there. Each reason names both values and what to
    change."""
    reasons = []
    if spec.task != stack.task:
        reasons.append(f"task kind: the file's actor runs the {spec.task!r} task, this executor's "
                       f"task.kind is {stack.task!r}")
    if spec.observation != stack.observation:
        reasons.append(f"observation kind: the file's is {spec.observation!r}, this executor's "
                       f"task.observation is {stack.observation!r}")
    if spec.state_dim != stack.state_dim:
        reasons.append(f"state size: the file's actor takes {spec.state_dim}-D states, this "
                       f"executor's are {stack.state_dim}-D")
    if spec.action_dim != stack.action_dim:
        reasons.append(f"action size: the file's actor gives {spec.action_dim}-D actions, this "
                       f"executor's task takes {stack.action_dim}-D")
    if robot_family(spec.robot) != robot_family(stack.robot):
        reasons.append(f"robot: the file was trained on {spec.robot!r} (family "
                       f"{robot_family(spec.robot)!r}), this stack drives {stack.robot!r} "
                       f"(family {robot_family(stack.robot)!r}; policy.robot)")
    if spec.task == stack.task and spec.observation == stack.observation:
        for name, value in spec.settings.items():
            if name in stack.settings and not _same(value, stack.settings[name]):
                reasons.append(f"setting {name}: the file's actor was trained with {value}, this "
                               f"executor has {stack.settings[name]}")
    return reasons


def check_compatible(spec: PolicySpec, stack: PolicySpec, path: Path | str = "") -> None:
    """:raises PolicyFileError: with every reason of :func:`mismatches`, if there is one."""
    reasons = mismatches(spec, stack)
    if reasons:
        where = f"policy file {path}" if path else "policy file"
        raise PolicyFileError(f"{where} does not fit this stack: " + "; ".join(reasons))


def _digest(layers: list[tuple[np.ndarray, np.ndarray]]) -> str:
    """SHA-256 of the layers' bytes in order (a changed or truncated weight is found)."""
    h = hashlib.sha256()
    for weight, bias in layers:
        for array in (weight, bias):
            h.update(str(array.shape).encode())
            h.update(np.ascontiguousarray(array, dtype=np.float32).tobytes())
    return h.hexdigest()


def _layers_from(actor: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    """(weight, bias) float32 pairs of an ``ActorMLP``, a :class:`Policy` or the
    ``(name, array)`` list of ``DDPG.actor_tensors``."""
    if hasattr(actor, "layers"):
        pairs = actor.layers
    else:
        arrays = [np.asarray(t) for _, t in actor]
        if len(arrays) % 2:
            raise PolicyFileError("expected weight/bias pairs")
        pairs = list(zip(arrays[0::2], arrays[1::2]))
    layers = [(np.asarray(w, dtype=np.float32), np.asarray(b, dtype=np.float32))
              for w, b in pairs]
    _check_layers(layers)
    return layers


def _check_layers(layers: list[tuple[np.ndarray, np.ndarray]]) -> None:
    if not layers:
        raise PolicyFileError("the actor has no layers")
    width = None
    for k, (weight, bias) in enumerate(layers):
        if weight.ndim != 2 or bias.shape != (weight.shape[0],):
            raise PolicyFileError(f"layer {k}: weight {weight.shape} and bias {bias.shape} do "
                                  "not form a dense layer")
        if width is not None and weight.shape[1] != width:
            raise PolicyFileError(f"layer {k} takes {weight.shape[1]} inputs, layer {k - 1} "
                                  f"gives {width}")
        if not (np.all(np.isfinite(weight)) and np.all(np.isfinite(bias))):
            raise PolicyFileError(f"layer {k} holds non-finite weights")
        width = weight.shape[0]


class Policy:
    """A frozen actor with its spec: ``policy(state)`` is the action in [-1, 1]^action_dim.

    The forward pass is ``ActorMLP``'s (float32, ``x @ W.T + b``, tanh), so a tanh actor gives
    the bits the executor computed in training.
    """

    def __init__(self, spec: PolicySpec, layers: list[tuple[np.ndarray, np.ndarray]]) -> None:
        _check_layers(layers)
        if layers[0][0].shape[1] != spec.state_dim or layers[-1][0].shape[0] != spec.action_dim:
            raise PolicyFileError(
                f"the actor maps {layers[0][0].shape[1]}-D states to {layers[-1][0].shape[0]}-D "
                f"actions, its spec says {spec.state_dim} -> {spec.action_dim}")
        self.spec = spec
        self.layers = layers
        self._hidden = ACTIVATIONS[spec.hidden_activation]

    @property
    def input_dim(self) -> int:
        """Length of the state the actor takes (as ``ActorMLP.input_dim``)."""
        return self.spec.state_dim

    def __call__(self, state: np.ndarray) -> np.ndarray:
        x = np.asarray(state, dtype=np.float32)
        if x.shape[-1:] != (self.spec.state_dim,):
            raise ValueError(f"the policy takes {self.spec.state_dim}-D states, got shape "
                             f"{x.shape}")
        last = len(self.layers) - 1
        for k, (weight, bias) in enumerate(self.layers):
            x = x @ weight.T + bias
            x = np.tanh(x) if k == last else self._hidden(x)
        return x.astype(np.float64)


def save_policy(path: Path | str, actor: Any, spec: PolicySpec) -> Path:
    """Write ``actor`` (``ActorMLP``, :class:`Policy` or ``DDPG.actor_tensors()``) with ``spec``
    to ``path`` (``.npz`` appended if it has no suffix); the path written.

    :raises PolicyFileError: if the actor's sizes are not the spec's.
    """
    layers = _layers_from(actor)
    Policy(spec, layers)                        # the same checks a reader makes
    path = Path(path)
    if not path.suffix:
        path = path.with_suffix(SUFFIX)
    header = {"format": FORMAT, "format_version": FORMAT_VERSION, **asdict(spec),
              "layers": len(layers), "sha256": _digest(layers)}
    arrays: dict[str, np.ndarray] = {"header": np.array(json.dumps(header, sort_keys=True))}
    for k, (weight, bias) in enumerate(layers):
        arrays[f"layer{k}.weight"], arrays[f"layer{k}.bias"] = weight, bias
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as handle:
        np.savez(handle, **arrays)
    return path


def load_policy(path: Path | str) -> Policy:
    """Read a policy file (numpy only, no pickle).

    :raises PolicyFileError: for a missing, unreadable or malformed file, another format, a
        newer format version, or weights whose digest is not the header's.
    """
    path = Path(path)
    if not path.is_file():
        raise PolicyFileError(f"policy file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise PolicyFileError(f"{path} is not a policy file (.npz): {exc}") from None
    try:
        header = json.loads(str(arrays.pop("header")))
    except (KeyError, json.JSONDecodeError):
        raise PolicyFileError(f"{path} has no policy header: not written by "
                              "`qgl export-policy`") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise PolicyFileError(f"{path}: format {header.get('format')!r}, expected {FORMAT!r}")
    version = header.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise PolicyFileError(f"{path}: format version {version!r}; this stack reads up to "
                              f"{FORMAT_VERSION} (update the stack)")
    try:
        count = int(header["layers"])
        layers = [(arrays[f"layer{k}.weight"], arrays[f"layer{k}.bias"]) for k in range(count)]
        spec = PolicySpec(**{name: header[name] for name in PolicySpec.__dataclass_fields__
                             if name in header})
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, PolicyFileError):
            raise
        raise PolicyFileError(f"{path}: malformed policy file ({exc!r})") from None
    layers = [(np.asarray(w, dtype=np.float32), np.asarray(b, dtype=np.float32))
              for w, b in layers]
    _check_layers(layers)
    if _digest(layers) != header.get("sha256"):
        raise PolicyFileError(f"{path}: the weights do not match the header's digest (a "
                              "damaged or edited file)")
    return Policy(spec, layers)


def frozen_policy(path: str, robot: str, task_kind: str, task: Any) -> Policy | None:
    """The executor's frozen actor: the policy file ``path`` checked against its ``task`` (of
    kind ``task_kind``) on ``robot``; ``None`` when ``path`` is "" (the learner's actor).

    :raises PolicyFileError: for a file that cannot be read or does not fit, with the reasons.
    """
    if not path:
        return None
    policy = load_policy(path)
    check_compatible(policy.spec, spec_for_task(task_kind, task, robot), path)
    return policy
