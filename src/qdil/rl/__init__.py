"""Policies, normalisers, rollouts, GAE and the PPO update: below the executors and the loop."""
