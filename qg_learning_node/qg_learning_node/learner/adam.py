"""Adam (Kingma & Ba 2015) for the DDPG networks, computed as ``torch.optim.Adam`` computes it
on the CPU, without ``torch.optim``.

Why not ``torch.optim.Adam``: every ``torch.optim`` optimizer marks its methods as not to be
traced by TorchDynamo, the tracer behind ``torch.compile``, and imports TorchDynamo the first
time one is built or stepped: 1.2 s of CPU, as much again as importing PyTorch, in every learner
start and every experiment worker. The learner never compiles.

What keeps the two the same: the update below is torch's single-tensor path (the one it takes
for CPU tensors) in its order of operations, so a seed trains the same networks to the bit; and
``state_dict`` has torch's layout, so a checkpoint of either optimizer loads into the other.
``tests/qg_core/test_adam.py`` checks both against ``torch.optim.Adam``.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import torch

__all__ = ["Adam"]

#: The settings ``torch.optim.Adam`` writes beside ``lr``, ``betas`` and ``eps`` in each
#: parameter group of its ``state_dict`` (this class has no others), so torch loads ours.
_TORCH_GROUP_DEFAULTS = {"weight_decay": 0, "amsgrad": False, "maximize": False, "foreach": None,
                         "capturable": False, "differentiable": False, "fused": None,
                         "decoupled_weight_decay": False}


class Adam:
    """Adam without weight decay or AMSGrad, over one group of parameters.

    The interface DDPG uses of ``torch.optim.Adam``: ``zero_grad``, ``step``, ``param_groups``
    (one group; its ``lr`` may be changed between steps) and ``state_dict``/``load_state_dict``.
    """

    def __init__(self, params: Iterable[torch.Tensor], lr: float = 1e-3,
                 betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8) -> None:
        """:raises ValueError: for no parameters, or a setting outside Adam's ranges."""
        self.params = list(params)
        if not self.params:
            raise ValueError("Adam got an empty parameter list")
        if not (lr >= 0.0 and eps >= 0.0 and all(0.0 <= beta < 1.0 for beta in betas)):
            raise ValueError(f"Adam needs lr >= 0, eps >= 0 and betas in [0, 1), got lr {lr}, "
                             f"betas {betas}, eps {eps}")
        self.param_groups = [{"params": self.params, "lr": lr, "betas": tuple(betas), "eps": eps}]
        #: Per parameter (with a gradient once): its step count and first and second moments.
        self.state: dict[torch.Tensor, dict[str, torch.Tensor]] = {}

    def zero_grad(self) -> None:
        """Drop the gradients (``torch.optim``'s default, ``set_to_none=True``)."""
        for param in self.params:
            param.grad = None

    @torch.no_grad()
    def step(self) -> None:
        """One Adam update of every parameter that has a gradient."""
        group = self.param_groups[0]
        lr, (beta1, beta2), eps = group["lr"], group["betas"], group["eps"]
        for param in self.params:
            if param.grad is None:
                continue
            state = self.state.get(param)
            if state is None:
                state = self.state[param] = {
                    "step": torch.tensor(0.0),
                    "exp_avg": torch.zeros_like(param, memory_format=torch.preserve_format),
                    "exp_avg_sq": torch.zeros_like(param, memory_format=torch.preserve_format)}
            exp_avg, exp_avg_sq = state["exp_avg"], state["exp_avg_sq"]
            state["step"] += 1
            exp_avg.lerp_(param.grad, 1 - beta1)
            exp_avg_sq.mul_(beta2).addcmul_(param.grad, param.grad, value=1 - beta2)
            step = state["step"].item()
            step_size = lr / (1 - beta1 ** step)
            denom = (exp_avg_sq.sqrt() / (1 - beta2 ** step) ** 0.5).add_(eps)
            param.addcdiv_(exp_avg, denom, value=-step_size)

    def state_dict(self) -> dict[str, Any]:
        """The moments and settings, in ``torch.optim.Adam``'s layout (parameters by index)."""
        index = {id(param): i for i, param in enumerate(self.params)}
        settings = {key: value for key, value in self.param_groups[0].items() if key != "params"}
        return {"state": {index[id(param)]: dict(state) for param, state in self.state.items()},
                "param_groups": [{**settings, **_TORCH_GROUP_DEFAULTS,
                                  "params": list(range(len(self.params)))}]}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Take the moments and settings of a ``state_dict`` (of this class or of torch's Adam).

        :raises ValueError: if it is of another number or shape of parameters, or of an Adam
            with weight decay or AMSGrad.
        """
        (group,) = state_dict["param_groups"]
        if len(group["params"]) != len(self.params):
            raise ValueError(f"the optimizer state is of {len(group['params'])} parameters, "
                             f"this optimizer has {len(self.params)}")
        if group.get("weight_decay", 0) or group.get("amsgrad", False):
            raise ValueError("the optimizer state is of an Adam with weight decay or AMSGrad")
        state: dict[torch.Tensor, dict[str, torch.Tensor]] = {}
        for i, saved in state_dict["state"].items():
            param = self.params[group["params"].index(i)]
            if saved["exp_avg"].shape != param.shape:
                raise ValueError(f"the optimizer state of parameter {i} has shape "
                                 f"{tuple(saved['exp_avg'].shape)}, the parameter "
                                 f"{tuple(param.shape)}")
            state[param] = {"step": saved["step"].detach().clone().to(torch.float32),
                            **{key: saved[key].detach().clone().to(param.dtype)
                               for key in ("exp_avg", "exp_avg_sq")}}
        self.state = state
        self.param_groups[0].update(lr=group["lr"], betas=tuple(group["betas"]), eps=group["eps"])
