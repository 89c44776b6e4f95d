"""The learner's Adam against ``torch.optim.Adam``: the same networks to the bit, and
checkpoints that load both ways."""
from __future__ import annotations

import pytest
import torch
from qg_learning_node.learner.adam import Adam


def _net(seed: int) -> torch.nn.Module:
    torch.manual_seed(seed)
    return torch.nn.Sequential(torch.nn.Linear(5, 16), torch.nn.ReLU(), torch.nn.Linear(16, 1))


def _train(net: torch.nn.Module, optimizer, steps: int, first: int = 0,
           lr_after: tuple[int, float] | None = None) -> None:
    """``steps`` updates on fixed random batches (batch ``first`` on); the learning rate is
    changed in the param group as DDPG's ``set_learning_rates`` does."""
    for k in range(first, first + steps):
        if lr_after is not None and k == lr_after[0]:
            optimizer.param_groups[0]["lr"] = lr_after[1]
        g = torch.Generator().manual_seed(k)
        x, y = torch.randn(32, 5, generator=g), torch.randn(32, 1, generator=g)
        optimizer.zero_grad()
        torch.mean((net(x) - y) ** 2).backward()
        optimizer.step()


def _same(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    return all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters(), strict=True))


def test_the_updates_are_torchs_to_the_bit() -> None:
    ours, theirs = _net(0), _net(0)
    _train(ours, Adam(ours.parameters(), lr=3e-3), 60, lr_after=(30, 1e-3))
    _train(theirs, torch.optim.Adam(theirs.parameters(), lr=3e-3), 60, lr_after=(30, 1e-3))
    assert _same(ours, theirs)
    assert not _same(ours, _net(0))                      # it did train


@pytest.mark.parametrize("first,then", [(Adam, torch.optim.Adam), (torch.optim.Adam, Adam)],
                         ids=["ours-then-torchs", "torchs-then-ours"])
def test_a_checkpoint_of_either_resumes_in_the_other(first, then) -> None:
    """20 steps, a state_dict, 20 more after loading it into the other class: as 40 steps of
    torch's Adam."""
    reference = _net(1)
    _train(reference, torch.optim.Adam(reference.parameters(), lr=1e-2), 40)
    net = _net(1)
    optimizer = first(net.parameters(), lr=1e-2)
    _train(net, optimizer, 20)
    resumed = then(net.parameters(), lr=0.5)                 # the saved lr wins
    resumed.load_state_dict(optimizer.state_dict())
    _train(net, resumed, 20, first=20)
    assert _same(net, reference)


def test_bad_settings_and_foreign_states_are_refused() -> None:
    net = _net(2)
    with pytest.raises(ValueError, match="empty parameter list"):
        Adam([], lr=1e-3)
    for bad in ({"lr": -1e-3}, {"betas": (0.9, 1.0)}, {"eps": float("nan")}):
        with pytest.raises(ValueError, match="Adam needs"):
            Adam(net.parameters(), **bad)
    optimizer = Adam(net.parameters())
    other = _net(3)
    with pytest.raises(ValueError, match="of 2 parameters, this optimizer has 4"):
        optimizer.load_state_dict(Adam(other[0].parameters()).state_dict())
    wide = torch.nn.Sequential(torch.nn.Linear(5, 8), torch.nn.ReLU(), torch.nn.Linear(8, 1))
    trained = Adam(wide.parameters())
    _train(wide, trained, 1)
    with pytest.raises(ValueError, match=r"shape \(8, 5\), the parameter \(16, 5\)"):
        optimizer.load_state_dict(trained.state_dict())
    decayed = torch.optim.Adam(other.parameters(), weight_decay=0.1)
    with pytest.raises(ValueError, match="weight decay or AMSGrad"):
        optimizer.load_state_dict(decayed.state_dict())
