"""Gymnasium environments (installed as ``fignet_gym.envs``)."""
