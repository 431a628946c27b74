"""Domain randomisation: distributions, physics parameters of an `MjModel`, observation and
action noise, and action latency. Everything draws from a generator handed in by the env."""

from taskforge.randomization.distributions import sample
from taskforge.randomization.noise import ActionBacklash, ActionLatency, AdditiveNoise
from taskforge.randomization.physics import PHYSICS_TARGETS, PhysicsRandomizer, PhysicsTarget, physics_target

__all__ = ["PHYSICS_TARGETS", "ActionBacklash", "ActionLatency", "AdditiveNoise", "PhysicsRandomizer", "PhysicsTarget", "physics_target", "sample"]
