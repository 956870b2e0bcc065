"""Small untrained simulators shared by the dynamics, env and agent tests."""

import torch

from fignet_gym.simulator.model import LearnedSimulator, SimulatorConfig

SMALL = dict(dt=0.02, latent_size=16, message_passing_steps=2)


def zero_simulator(scene_type: str = "", dt: float = 0.02) -> LearnedSimulator:
    """An untrained model whose network outputs exactly zero: objects keep their velocity."""
    sim = LearnedSimulator(SimulatorConfig(**{**SMALL, "dt": dt}, scene_type=scene_type)).eval()
    with torch.no_grad():
        for p in sim.net.parameters():
            p.zero_()
    return sim


def quiet_simulator(scene_type: str = "", dt: float = 0.02) -> LearnedSimulator:
    """An untrained model with small output statistics: junk motion, but bounded."""
    sim = LearnedSimulator(SimulatorConfig(**{**SMALL, "dt": dt}, scene_type=scene_type)).eval()
    sim.target_norm.accumulate(torch.randn(1000, 3, dtype=torch.float64) * 1e-4)
    return sim


def wild_simulator(scene_type: str = "", dt: float = 0.02) -> LearnedSimulator:
    """An untrained model with huge accelerations: it diverges on its first step."""
    sim = LearnedSimulator(SimulatorConfig(**{**SMALL, "dt": dt}, scene_type=scene_type)).eval()
    sim.target_norm.accumulate(torch.randn(1000, 3, dtype=torch.float64) * 50.0)
    return sim
