"""Agents: PPO helpers, planners, sim-to-real (installed as ``fignet_gym.agents``)."""
