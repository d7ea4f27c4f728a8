"""The plain multilayer perceptron every method's networks are built from."""

from __future__ import annotations

from torch import nn

__all__ = ["mlp"]


def mlp(n_in: int, n_out: int, hidden: tuple[int, ...], activation: str) -> nn.Sequential:
    """Plain MLP ``n_in -> hidden... -> n_out``."""
    act = {"relu": nn.ReLU, "tanh": nn.Tanh}[activation]
    layers: list[nn.Module] = []
    width = n_in
    for h in hidden:
        layers += [nn.Linear(width, h), act()]
        width = h
    layers.append(nn.Linear(width, n_out))
    return nn.Sequential(*layers)
