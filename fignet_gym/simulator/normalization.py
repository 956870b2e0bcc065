"""Online feature normalisation (zero mean, unit variance), as in MeshGraphNets."""

from __future__ import annotations

import torch
from torch import Tensor, nn


class Normalizer(nn.Module):
    """Accumulates running statistics while ``accumulate`` is requested and normalises with them.

    Statistics are kept in float64 buffers (saved in checkpoints). Accumulation stops after
    ``max_accumulations`` calls, so statistics settle early in training and the model's input
    distribution stops moving.
    """

    def __init__(self, size: int, max_accumulations: int = 10_000, std_epsilon: float = 1e-8) -> None:
        super().__init__()
        self.max_accumulations = max_accumulations
        self.std_epsilon = std_epsilon
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))
        self.register_buffer("calls", torch.zeros((), dtype=torch.float64))
        self.register_buffer("total", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("total_sq", torch.zeros(size, dtype=torch.float64))

    def accumulate(self, x: Tensor) -> None:
        """Add a batch ``float[M, size]`` to the statistics (no-op once saturated or empty)."""
        if x.shape[0] == 0 or self.calls >= self.max_accumulations:
            return
        xd = x.detach().double()
        self.count += xd.shape[0]
        self.calls += 1
        self.total += xd.sum(0)
        self.total_sq += (xd * xd).sum(0)

    @property
    def mean(self) -> Tensor:
        """``float64[size]``."""
        return self.total / self.count.clamp_min(1.0)

    @property
    def std(self) -> Tensor:
        """``float64[size]``, at least ``std_epsilon``."""
        var = self.total_sq / self.count.clamp_min(1.0) - self.mean**2
        std = var.clamp_min(0.0).sqrt().clamp_min(self.std_epsilon)
        # An untrained model (no statistics yet) normalises by 1, not by epsilon.
        return torch.where(self.count > 1, std, torch.ones_like(std))

    def forward(self, x: Tensor, accumulate: bool = False) -> Tensor:
        """Normalise ``float[M, size]``, accumulating first if asked."""
        if accumulate:
            self.accumulate(x)
        return (x - self.mean.to(x.dtype)) / self.std.to(x.dtype)

    def inverse(self, y: Tensor) -> Tensor:
        """Undo :meth:`forward`: ``float[M, size] -> float[M, size]``."""
        return y * self.std.to(y.dtype) + self.mean.to(y.dtype)
